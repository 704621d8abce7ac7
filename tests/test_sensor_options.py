"""track3d.sensor_options: the tables agree with the sensors the simulator makes and with Track3D."""
import inspect

import pytest

from track3d import sensor_options as so
from track3d.camera import Camera
from track3d.tracker import Track3D

TABLES = {name: getattr(so, name) for name in so.__all__ if name.startswith("SENSOR_")}


def test_the_tables_are_found():
    # the module's own listing holds every table below; an empty scan would pass the rest vacuously
    assert len(TABLES) >= 18
    assert all(isinstance(t, dict) for t in TABLES.values())


@pytest.mark.parametrize("name", sorted(TABLES))
def test_every_table_key_is_a_sensor(name):
    # a misspelt key ("flash_lidar") would silently give that sensor the default option
    assert set(TABLES[name]) <= set(so.DEPTH_SENSORS), name


def test_the_sensors_are_the_simulators():
    sensors = pytest.importorskip("track3d_sim.sensors")
    assert set(so.DEPTH_SENSORS) == set(sensors.DEPTH_SENSORS)


@pytest.mark.parametrize("sensor", [None, *so.DEPTH_SENSORS])
def test_options_are_track3d_keywords(sensor):
    opts = so.sensor_options(sensor)
    params = inspect.signature(Track3D.__init__).parameters
    assert set(opts) <= set(params)
    t = Track3D.create(Camera.from_fov(64, 48, 45.0), tracker="kcf", estimator="baseline", **opts)
    for key in ("frustum_margin", "weight_3d", "weight_2d", "dark_side", "fusion_cover"):
        assert getattr(t, key) == opts[key]


def test_unknown_sensor_gets_the_defaults():
    opts = so.sensor_options(None)
    assert opts["frustum_margin"] == so.FRUSTUM_MARGIN
    assert opts["silhouette"] == so.SILHOUETTE
    assert opts["body_views"] is so.BODY_VIEWS
    assert opts["resume_outline"] is False


def test_names_are_case_blind_and_checked():
    assert so.sensor_options("Stereo") == so.sensor_options("stereo")
    assert so.check_depth_sensor("ToF") == "tof"
    assert so.check_depth_sensor(None) is None
    with pytest.raises(ValueError, match="depth_sensor must be one of"):
        so.check_depth_sensor("sterio")
    with pytest.raises(ValueError):
        so.check_depth_sensor(3)


def test_the_names_track3d_tracker_exported_still_import_from_it():
    # they were in track3d.tracker.__all__ before the tables moved: a caller's import must not break
    import track3d.tracker as T

    for name in ("FRUSTUM_MARGIN", "frustum_margin_for", "fusion_weight_for", "section_weight_for",
                 "section_limbs_for", "measured_faces_for", "sensor_options", "DEPTH_SENSORS", "check_depth_sensor"):
        assert name in T.__all__ and getattr(T, name) is getattr(so, name), name
