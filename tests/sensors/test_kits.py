import pytest

from wearpose.sensors import KitError, SensorKit, SensorSpec, get_kit, list_kits, resolve_sites
from wearpose.sensors.kits import SENSOR_KINDS

ANNY_SITES = ["head", "sternum", "back_upper", "pelvis"] + [
    lr + p for p in ("upper_arm", "forearm", "wrist", "thigh", "shin", "foot", "shoulder") for lr in ("left_", "right_")]


def test_registry_contents():
    assert set(list_kits()) >= {"em12", "em6", "imu6", "mimu6", "miposer", "miposer1"}
    assert len(get_kit("em12").sensors) == 12 and len(get_kit("em6").sensors) == 6
    assert get_kit("em12").em_source_site == "pelvis"
    # EM-POSE 6: wrists (lower arms), lower legs, head, back
    assert set(get_kit("em6").sensor_names) == {"back", "head", "left_lower_arm", "right_lower_arm",
                                                  "left_lower_leg", "right_lower_leg"}
    assert [s.site for s in get_kit("imu6").sensors] == ["left_forearm", "right_forearm", "left_shin", "right_shin",
                                                          "head", "pelvis"]
    mp = get_kit("miposer")
    assert mp.em_source_site == "head" and {s.kind for s in mp.sensors} == {"vio", "em6dof", "imu"}
    assert len(get_kit("miposer1").of_kind("em6dof")) == 1
    for k in list_kits():
        assert all(s.kind in SENSOR_KINDS for s in get_kit(k).sensors)


def test_unknown_kit_lists_available():
    with pytest.raises(KitError) as e:
        get_kit("em13")
    assert "em13" in str(e.value) and "em12" in str(e.value) and "imu6" in str(e.value)


def test_missing_site_names_site_and_asset():
    with pytest.raises(KitError) as e:
        resolve_sites(get_kit("imu6"), ["head", "left_forearm"], "tiny-test")
    msg = str(e.value)
    assert "right_forearm" in msg and "tiny-test" in msg and "imu6" in msg


def test_all_kits_fit_the_anny_site_list():
    import warnings

    for k in list_kits():
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no built-in kit needs a substitution on the embedded asset
            sites, subs = resolve_sites(get_kit(k), ANNY_SITES, "wearpose-anny-v1")
        assert subs == {}
        assert all(sites[s.name] == s.site for s in get_kit(k).sensors)
    sites, _ = resolve_sites(get_kit("em12"), ANNY_SITES)
    assert sites["left_shoulder"] == "left_shoulder" and sites["right_shoulder"] == "right_shoulder"


def test_fallback_site_is_reported():
    kit = SensorKit("fb", (SensorSpec("a", "imu", "left_scapula", 60, fallback_sites=("nowhere", "back_upper")),))
    with pytest.warns(UserWarning, match="left_scapula -> back_upper"):
        sites, subs = resolve_sites(kit, ANNY_SITES, "wearpose-anny-v1")
    assert sites == {"a": "back_upper"} and subs == {"a": "left_scapula -> back_upper"}


def test_bad_specs_rejected():
    with pytest.raises(KitError):
        SensorSpec("a", "gps", "head", 60)
    with pytest.raises(KitError):
        SensorSpec("a", "imu", "head", 0)
    with pytest.raises(KitError):
        SensorKit("x", (SensorSpec("a", "em6dof", "head", 60),))
    with pytest.raises(KitError):
        SensorKit("x", (SensorSpec("a", "imu", "head", 60), SensorSpec("a", "imu", "pelvis", 60)))
    assert get_kit("imu6").with_rate(30).rates == (30.0,)
