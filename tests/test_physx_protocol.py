"""PhysX overall-description protocol: the real texts, the variations, round trips, frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from generation.physx.description import MovementType, write_description
from generation.physx.grid_frame import GridFrame, group_joint
from generation.physx.basic_info import description_from_basic_info
from generation.physx.protocol import ProtocolError, parse_description
from scene_builder.model import JointType
from tests.conftest import PHYSX_PROTOCOL, require


def _real_text() -> str:
    return (require(PHYSX_PROTOCOL) / "PhysX-Anything" / "41452_basic_info.txt").read_text()


def test_real_description_matches_upstream_parser_json_field_by_field():
    desc, report = parse_description(_real_text())
    assert report.clean
    ref = json.loads((PHYSX_PROTOCOL / "derived" / "41452_basic_info.PhysX-Anything-parser.json").read_text())
    assert (desc.name, desc.category) == (ref["object_name"], ref["category"])
    assert desc.dimension_cm == tuple(float(v) for v in ref["dimension"].split("*"))
    for part, r in zip(desc.parts, ref["parts"], strict=True):
        assert (part.label, part.name, part.material, part.affordance_rank, part.description) == (
            r["label"], r["name"], r["material"], r["priority_rank"], r["Basic_description"])
        assert part.density_kg_m3 == pytest.approx(float(r["density"].split("g/cm")[0]) * 1000.0)
        assert part.youngs_modulus_pa == pytest.approx(float(r["Young's Modulus (GPa)"]) * 1e9)
        assert part.poisson_ratio == pytest.approx(float(r["Poisson's Ratio"]))
    assert list(desc.groups[0].members) == ref["group_info"]["0"]
    members, parent, params, kind = ref["group_info"]["1"]
    g = desc.groups[1]
    assert (list(g.members), str(g.parent), g.movement.value) == (members, parent, kind)
    grid = desc.grid
    mine = list(g.axis_direction) + [v / grid - 0.5 for v in g.axis_position_vox] + [v / 180 for v in g.revolute_range_deg]
    assert np.allclose(mine, params)


def test_writer_reproduces_the_real_target_byte_for_byte_and_round_trips():
    text = _real_text()
    desc, _ = parse_description(text)
    assert write_description(desc) == text
    for sep in (", ", "| "):
        again, report = parse_description(write_description(desc, sep))
        assert again == desc and report.clean


def test_physx_omni_basic_info_json_loads_and_round_trips_through_text():
    data = json.loads((require(PHYSX_PROTOCOL) / "physx-omni-play" / "basic_info.json").read_text())
    desc, report = description_from_basic_info(data, grid=64)
    assert report.clean and len(desc.parts) == 7 and len(desc.groups) == 6
    lid = desc.groups[2]
    assert lid.movement is MovementType.REVOLUTE and lid.members == (2,)
    # README G6: the lid came from direction [0, 1, 0], position [13.34, 0, 52.5], range [-180, 0]
    assert lid.axis_direction == (0.0, 1.0, 0.0)
    assert np.allclose(lid.axis_position_vox, [13.34, 0.0, 52.5]) and lid.revolute_range_deg == (-180.0, 0.0)
    assert desc.part(0).density_kg_m3 == pytest.approx(4450.0) and desc.part(0).youngs_modulus_pa == pytest.approx(100.005e9)
    text = write_description(desc)
    assert "l_0: Caster Wheel (Front Right)| 7| Steel with Rubber| 4.45 g/cm^3|" in text
    again, report = parse_description(text, grid=64)
    assert again == desc and report.clean


PAPER_COMMA = (
    "Name: Toy Car\nCategory: Vehicle\nDimension: 30*15*12\n\nParts:\n"
    "l_0: Car Body, 1, Carbon Fiber Reinforced Polymer, 1.6 g/cm^3, 70.0, 0.3, The main chassis, painted red.\n"
    "l_1: Wheel, Front Left, 2, Rubber, 1100 kg/m^3, 50 MPa, 0.45-0.49, A wheel\n"
    "l_2: Lid| 3| Plastic| 0.5-0.7| 2.0| 0.4| top lid\n"
    "Group_info:\n"
    "group_0: [l_0]; Type: E; Params: N/A\n"
    "group_1: [l_1] (child); Type: C relative to group_0 (parent); Params: direction: [0,1,0], axis position (in voxel grid): [10, 0, 5], revolute range (degree): [-180,180]\n"
    "group_2: ['l_2']; Type: B relative to group_0; Param: direction: [0, 0, 1], slide range (in voxel grid): [4, 0]"
)


def test_variations_are_read_and_repairs_reported():
    desc, report = parse_description(PAPER_COMMA, grid=64)
    body, wheel, lid = desc.parts
    assert body.description == "The main chassis, painted red." and body.density_kg_m3 == 1600.0
    assert wheel.name == "Wheel, Front Left" and wheel.density_kg_m3 == 1100.0
    assert wheel.youngs_modulus_pa == 50e6 and wheel.poisson_ratio == pytest.approx(0.47)
    assert lid.density_kg_m3 == pytest.approx(600.0)  # "0.5-0.7" is a range, not 0.5 and -0.7
    assert desc.groups[1].movement is MovementType.REVOLUTE and desc.groups[2].slide_range_vox == (0.0, 4.0)
    text = "\n".join(report.warnings)
    assert "name contains 1 comma" in text and "midpoint" in text and "re-sorted" in text
    again, _ = parse_description(write_description(desc), grid=64)
    assert again == desc


def test_broken_groups_are_repaired():
    text = (
        "Name: X\nCategory: Y\nDimension: 10*10*10\nParts:\n"
        "l_0: a| 1| Wood| 0.7| 10| 0.3| d\nl_1: b| 2| Wood| 0.7| 10| 0.3| d\nl_2: c| 99| Wood| 0.7| 10| 0.7| d\n"
        "group_0: ['l_0', 'l_7']; Type: E; Param: N/A\n"
        "group_1: ['l_1']; Type: C relative to group_5; Param: direction: [0, 0, 0], axis position (in voxel grid): [1, 2, 3], revolute range (degree): [0, 90]\n"
        "some chatter from the model"
    )
    desc, report = parse_description(text, grid=32)
    assert desc.groups[0].members == (0, 2)  # l_7 dropped, l_2 (in no group) fixed to the base
    assert desc.groups[1].movement is MovementType.FIXED and desc.groups[1].parent == 0
    assert desc.part(2).affordance_rank == 10 and desc.part(2).poisson_ratio == 0.49
    assert len(report.warnings) >= 6


@pytest.mark.parametrize("text", ["", "hello world", "Name: a\nCategory: b\n<<<>>>"])
def test_unreadable_description_raises_one_line_error(text):
    with pytest.raises(ProtocolError) as err:
        parse_description(text)
    assert isinstance(err.value, ValueError) and "\n" not in str(err.value)


def test_grid_frame_uses_all_three_dimensions_and_maps_joints():
    desc, _ = parse_description(_real_text())
    frame, _ = GridFrame.from_dimension(desc.dimension_cm, 32)
    # without voxels: box centred in the grid with extents G * D / max(D); origin at its bottom
    corners = frame.to_asset(np.array([[0, 16 - 6.4, 16 - 12.8], [32, 16 + 6.4, 16 + 12.8]]))
    assert np.allclose(np.abs(corners[1] - corners[0]), [0.40, 1.00, 0.80]) and np.isclose(corners[:, 2].min(), 0.0)
    joint, _ = group_joint(desc.groups[1], frame, np.array([16.0, 11.0, 11.0]))
    assert joint.type is JointType.REVOLUTE and np.allclose(joint.axis, [0, 1, 0])
    assert np.isclose(joint.lower, np.radians(-122)) and joint.upper == 0.0
    # hinge at voxel y = 12.95, z = 17.8 -> asset x = -(12.95 - 16) * 1/32 m, z = (17.8 - 3.2) / 32 m
    assert np.allclose(joint.anchor_m, [3.05 / 32, 0.0, 14.6 / 32])
