"""Pose outputs of ``wearpose serve --output NAME`` (several at once), fed every published pose:

- ``vmc``: the Virtual Motion Capture protocol over OSC/UDP (:mod:`.vmc`), Unity humanoid bones
  in Unity's left-handed frame, for VSeeFace, Warudo, VNyan, Unity;
- ``lsl``: a Lab Streaming Layer outlet of poses per subject (:mod:`.lsl`): local joint
  rotations, root translation, per-joint uncertainty.

An output is an object with ``pose(PosePacket, rate_hz)`` (called on the server's event loop:
it must not block), ``stats()`` and ``close()``. Details: ``docs/devices.md``.
"""

from wearpose.errors import ConfigError
from wearpose.stream.outputs.lsl import LslPoseOutput
from wearpose.stream.outputs.vmc import VmcOutput

OUTPUTS = ("vmc", "lsl")

__all__ = ["OUTPUTS"]


def make_output(name: str, *, vmc_host: str = "127.0.0.1", vmc_port: int = 39539, vmc_subject: int = 0,
                lsl_name: str = "wearpose-poses") -> object:
    """The pose output ``name`` (``vmc``, ``lsl``) with its options (``wearpose serve``'s)."""
    if name == "vmc":
        return VmcOutput(vmc_host, vmc_port, vmc_subject)
    if name == "lsl":
        return LslPoseOutput(lsl_name)
    raise ConfigError(f"--output {name!r}: expected one of {', '.join(OUTPUTS)}")


__all__ += ["make_output"]
