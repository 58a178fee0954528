"""Live device inputs of ``wearpose serve --input NAME`` behind one interface
(:class:`~wearpose.stream.inputs.base.LiveInput`), each with a loopback emulator
(``wearpose stream emulate NAME RECORDING``):

- ``lsl``: Lab Streaming Layer inlet (:mod:`.lsl`; channel metadata names sensor, quantity, unit);
- ``osc``: OSC bundles with a YAML address map per device profile (:mod:`.osc`; ``ngimu``, ``generic``);
- ``mvn``: the Xsens MVN network streamer over UDP (:mod:`.mvn`; tracker kinematics, pose datagrams);
- ``ximu3``: x-io x-IMU3 devices through the official ``ximu3`` package (:mod:`.ximu3`; TCP or UDP,
  inertial and quaternion messages, binary or ASCII).

Contract and per-input details: ``docs/devices.md``.
"""

from wearpose.stream.inputs.base import DeviceFrame, LiveInput, canonical_channels, canonical_frame
from wearpose.errors import ConfigError
from wearpose.stream.inputs.lsl import LslInput, emulate_lsl
from wearpose.stream.inputs.mvn import MvnInput, emulate_mvn
from wearpose.stream.inputs.ximu3 import Ximu3Input, emulate_ximu3

#: Input name -> module holding its ``*Input`` class and ``emulate_*`` coroutine.
INPUTS = ("lsl", "osc", "mvn", "ximu3")

__all__ = ["DeviceFrame", "LiveInput", "canonical_channels", "canonical_frame", "INPUTS"]


def make_input(name: str, *, host: str = "127.0.0.1", rate: float | None = None, lsl_stream: str = "wearpose-sensors",
               osc_profile: str = "ngimu", osc_sensors: dict[str, int] | list[str] | None = None, osc_port: int = 9000,
               mvn_port: int = 9763, mvn_segments: list[str] | None = None, mvn_character: int = 0,
               mvn_position_unit: str = "m", mvn_pose_subject: int | None = None,
               ximu3_sensors: dict[str, int] | None = None, ximu3_transport: str = "tcp") -> LiveInput:
    """The live input ``name`` (``lsl``, ``osc``, ``mvn``, ``ximu3``) with its options (``wearpose serve``'s)."""
    if name == "lsl":
        return LslInput(lsl_stream, rate)
    if name == "osc":
        # start-up: the osc input (yaml, its profiles) adds ~114 ms to import wearpose.stream.inputs
        from wearpose.stream.inputs.osc import OscInput

        if not osc_sensors:
            raise ConfigError("--input osc: name the sensors, --osc-sensor NAME=PORT (one UDP port per device, "
                              "profile ngimu) or --osc-sensor NAME (profiles with {sensor} addresses, on --osc-port)")
        if rate is None:
            raise ConfigError("--input osc: give the devices' send rate, --device-rate HZ (OSC carries no rate)")
        try:
            return OscInput(osc_profile, osc_sensors, rate, host, osc_port)
        except ValueError as exc:
            raise ConfigError(f"--input osc: {exc}") from None
    if name == "mvn":
        try:
            return MvnInput(host, mvn_port, mvn_segments, rate or 60.0, mvn_character, mvn_position_unit,
                            pose_subject=mvn_pose_subject)
        except ValueError as exc:
            raise ConfigError(f"--input mvn: {exc}") from None
    if name == "ximu3":
        if not ximu3_sensors or not isinstance(ximu3_sensors, dict):
            raise ConfigError("--input ximu3: name the devices, --ximu3-sensor NAME=PORT (tcp: the device's TCP port "
                              "on --device-host; udp: the local port the device sends to)")
        if rate is None:
            raise ConfigError("--input ximu3: give the devices' message rate, --device-rate HZ")
        try:
            return Ximu3Input(ximu3_sensors, rate, host, ximu3_transport)
        except ValueError as exc:
            raise ConfigError(f"--input ximu3: {exc}") from None
    raise ConfigError(f"--input {name!r}: expected one of {', '.join(INPUTS)}")


async def emulate_input(name: str, recording: object, *, host: str = "127.0.0.1", port: int | None = None,
                  lsl_stream: str = "wearpose-sensors", osc_profile: str = "ngimu",
                  osc_ports: dict[str, int] | None = None, ximu3_ports: dict[str, int] | None = None,
                  ximu3_transport: str = "tcp", ximu3_format: str = "binary", **kw: object) -> dict:
    """Play ``recording`` as input ``name``'s device on ``host`` (loopback emulators; ``kw``:
    ``faults``, ``speed``, ``duration``, ``realtime``)."""
    if name == "lsl":
        return await emulate_lsl(recording, lsl_stream, **kw)
    if name == "osc":
        # start-up: the osc input (yaml, its profiles) adds ~114 ms to import wearpose.stream.inputs
        from wearpose.stream.inputs.osc import emulate_osc

        return await emulate_osc(recording, osc_profile, host, port or 9000, osc_ports, **kw)
    if name == "mvn":
        return await emulate_mvn(recording, host, port or 9763, **kw)
    if name == "ximu3":
        return await emulate_ximu3(recording, host, port or 7000, ximu3_ports, transport=ximu3_transport,
                                   fmt=ximu3_format, **kw)
    raise ConfigError(f"emulate {name!r}: expected one of {', '.join(INPUTS)}")


__all__ += ["make_input", "emulate_input"]
