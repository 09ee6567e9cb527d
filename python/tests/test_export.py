"""`cbd export` of a model fitted from Python: the kinematics file as xacro's loader reads it (PyYAML,
YAML 1.1: every value a number, not a string), the URDF as an XML parser reads it."""

import xml.etree.ElementTree as ET

import yaml

from conftest import UR5, run


def test_exported_files_read_as_ros_reads_them(ur5_fit, cbd_bin, tmp_path):
    model, _ = ur5_fit
    model.save(tmp_path / "ur5.blob")
    out = run(cbd_bin, "export", "--model", UR5 / "ur5.toml", "--blob", tmp_path / "ur5.blob", "--urdf", tmp_path / "ur5.urdf",
              "--ur-kinematics", tmp_path / "k.yaml", "--data", UR5 / "test.csv")
    assert "URDF alone" in out and "with the runtime's correction" in out, out
    k = yaml.safe_load((tmp_path / "k.yaml").read_text())["kinematics"]
    for segment in ["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"]:
        for key in ["x", "y", "z", "roll", "pitch", "yaw"]:
            value = k[segment][key]
            assert isinstance(value, (int, float)) and not isinstance(value, bool), f"{segment}.{key} = {value!r}"
    assert k["hash"].startswith("cbd_")
    robot = ET.parse(tmp_path / "ur5.urdf").getroot()
    joints = robot.findall("joint")
    assert [j.get("type") for j in joints] == ["fixed"] + ["continuous"] * 6 + ["fixed"]
    for j in joints:
        origin = j.find("origin")
        assert len([float(v) for v in origin.get("xyz").split() + origin.get("rpy").split()]) == 6
    assert robot.find(".//calibration") is None
