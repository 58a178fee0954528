"""wearpose: full-body, SMPL-compatible human motion from a few body-worn sensors.

Modules (lower ones never import higher ones): ``geometry``, ``body``, ``motion``, ``sensors``,
``recording``, ``calibration``, ``interference``, ``physics``, ``estimators``, ``evaluate``,
``viewer``, ``export``, ``stream``, ``cli``. See ``docs/architecture.md``.
"""

from wearpose.errors import WearposeError

__version__ = "0.1.0"
__all__ = ["WearposeError", "__version__"]
