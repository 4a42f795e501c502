"""Resource paths of a URDF written elsewhere (``aacmm_pin.outputs.urdf_resources``)."""

from __future__ import annotations

from pathlib import Path

from lxml import etree

from aacmm_pin.outputs.urdf_resources import rebase_resources

URDF = """<robot name="r">
  <gazebo><plugin filename="libgazebo_ros_control.so" name="ros_control"/></gazebo>
  <link name="a"><visual><geometry><mesh filename="meshes/a.stl"/></geometry>
    <material name="m"><texture filename="textures/t.png"/></material></visual></link>
</robot>"""


def test_only_mesh_and_texture_paths_are_rebased(tmp_path: Path) -> None:
    """Meshes and textures are rewritten to hold from the output folder; a Gazebo plugin's
    library name (example-robot-data's UR5 has one) is left as written."""
    root = etree.fromstring(URDF)
    assert rebase_resources(root, tmp_path / "arm", tmp_path / "cal") == 2
    assert root.find("gazebo/plugin").get("filename") == "libgazebo_ros_control.so"
    assert root.find("link/visual/geometry/mesh").get("filename") == "../arm/meshes/a.stl"
    assert root.find("link/visual/material/texture").get("filename") == "../arm/textures/t.png"
