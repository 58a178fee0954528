"""SensorInfo.site is checked against the known body sites when a recording is built or loaded
(issue 22: a kit's sensor name given as the site used to fail only at calibration)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from recording_testutils import two_sensor_recording
from wearpose.errors import InputFileError, ShapeError
from wearpose.recording import SensorInfo, load_recording, recording_arrays
from wearpose.recording.types import known_sites


def test_kit_sensor_name_as_site_is_refused_at_load_with_the_site(tmp_path) -> None:
    arrays = recording_arrays(two_sensor_recording())
    header = json.loads(str(arrays["header"]))
    header["sensors"][0]["site"] = "left_lower_leg"  # imu6's sensor name; the sensor is worn on 'left_shin'
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "site.npz", **arrays)
    with pytest.raises(InputFileError) as ei:
        load_recording(tmp_path / "site.npz")
    e = ei.value
    assert e.field == "sensors/left_forearm/site" and "unknown body site 'left_lower_leg'" in e.problem
    assert "the sensor 'left_lower_leg' of kits em12, em6, imu6, mimu6 is worn on site 'left_shin'" in e.problem
    assert "did you mean 'left_shin'?" in e.expected and str(tmp_path / "site.npz") in str(e)


def test_site_typo_suggests_the_nearest_known_sites() -> None:
    with pytest.raises(ShapeError, match=r"sensors/w/site: unknown body site 'left_wirst'.*did you mean 'left_wrist'"):
        SensorInfo("w", "imu", site="left_wirst")  # refused on construction too, not at calibration
    with pytest.raises(ShapeError, match=r"did you mean 'head'\?"):
        SensorInfo("h", "imu", site="Head")
    with pytest.raises(ShapeError, match=r"the sensor 'root' of kit mimu6 is worn on site 'pelvis'"):
        SensorInfo("r", "mimu", site="root")
    assert SensorInfo("w", "imu", site="left_wrist").site == "left_wrist" and SensorInfo("n", "imu").site is None


def test_known_sites_are_the_body_asset_sites_and_every_kit_site() -> None:
    from wearpose.body import BodyModel
    from wearpose.sensors import get_kit, list_kits

    sites = known_sites()
    assert set(BodyModel().site_names) <= sites
    assert all(s.site in sites for k in list_kits() for s in get_kit(k).sensors)


def test_a_registered_kit_brings_its_sites() -> None:
    from wearpose.sensors import SensorKit, SensorSpec, register_kit
    from wearpose.sensors.kits import _REGISTRY

    with pytest.raises(ShapeError):
        SensorInfo("c", "imu", site="left_ear")
    register_kit(SensorKit("test_ear_kit", (SensorSpec("ear", "imu", "left_ear", 60.0),)))
    try:
        assert SensorInfo("c", "imu", site="left_ear").site == "left_ear"
    finally:
        del _REGISTRY["test_ear_kit"]
