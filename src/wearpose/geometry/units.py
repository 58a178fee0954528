"""Unit constants. Internally: metres, seconds, radians, kilograms, newtons.

Degrees and millimetres appear only in reports and on the command line, converted with these.
"""

import math

CM_TO_M = 0.01
MM_TO_M = 0.001
M_TO_MM = 1000.0
M_TO_CM = 100.0
INCH_TO_M = 0.0254
DEG_TO_RAD = math.pi / 180.0
RAD_TO_DEG = 180.0 / math.pi
#: Gravity vector in the wearpose world (Y up), m/s^2.
GRAVITY = (0.0, -9.81, 0.0)
