"""A bundled robot is built from its record without parsing the generated URDF (issue 32):
the result must be the Robot that parsing the text gives, to the bit, for every record."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from olp_compensate.data import data_folder
from olp_compensate.errors import ModelError
from olp_compensate.kinematics.record_urdf import urdf_from_record
from olp_compensate.kinematics.records import record_from_dict
from olp_compensate.kinematics.robot import (bundled_record, bundled_robot_names, load_robot,
                                             ranges_from_edge_units, robot_from_record,
                                             robot_from_urdf_text)

RECORDS = [n for n in bundled_robot_names() if bundled_record(n) is not None]


def parsed_route(record):
    """The robot as it was made before: the record's URDF text read by the XML parser."""
    text = urdf_from_record(record)
    robot = robot_from_urdf_text(text, name=record.name, source=record.source,
                                 urdf_from_controller=record.coupling)
    return dataclasses.replace(robot, record=record,
                               axis_ranges=ranges_from_edge_units(robot, record.axis_ranges_deg))


def same(a, b) -> bool:
    """Equal values, arrays equal to the byte (so -0.0 is not 0.0: the fingerprint hashes
    bytes), dataclasses field by field whatever their ``compare``."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                and a.shape == b.shape and a.tobytes() == b.tobytes())
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(same(getattr(a, f.name), getattr(b, f.name))
                                          for f in dataclasses.fields(a))
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(map(same, a, b))
    if isinstance(a, float) and isinstance(b, float):
        return a.hex() == b.hex()
    return type(a) is type(b) and a == b


def test_every_bundled_robot_is_a_record():
    assert len(RECORDS) >= 40  # the routes are compared on all of them below


@pytest.mark.parametrize("name", RECORDS)
def test_direct_route_is_the_parsed_route(name):
    record = bundled_record(name)
    direct, parsed = load_robot(name), parsed_route(record)
    for field in dataclasses.fields(direct):
        assert same(getattr(direct, field.name), getattr(parsed, field.name)), field.name
    assert direct.fingerprint == parsed.fingerprint


def test_the_comparison_sees_a_sign_of_zero():
    """The check above would miss nothing: a -0.0 in one frame is a difference."""
    assert not same(np.array([0.0]), np.array([-0.0]))
    assert not same(-0.0, 0.0)


def record_doc(**changes) -> dict:
    """The bundled IRB 2400 record's document with ``changes``."""
    doc = json.loads((data_folder("robots") / "abb_irb2400.robot.json").read_text("utf-8"))
    doc.update(changes)
    return doc


@pytest.mark.parametrize("model", ["IRB 2400---x", "IRB\x01 2400", "IRB ---- 2400", "IRB \ufffe"])
def test_a_record_no_xml_comment_can_hold_fails_as_before(model):
    """A maker or model the generated URDF cannot carry is the parser's error, as it was."""
    record = record_from_dict(record_doc(model=model), "odd.robot.json")
    with pytest.raises(ModelError) as direct:
        robot_from_record(record)
    with pytest.raises(ModelError) as parsed:
        parsed_route(record)
    assert str(direct.value) == str(parsed.value)


@pytest.mark.parametrize("model", ["IRB 2400 <&> \"x\"", "IRB-2400 -x-"])
def test_odd_but_valid_models_take_the_direct_route_alike(model):
    record = record_from_dict(record_doc(model=model), "odd.robot.json")
    direct, parsed = robot_from_record(record), parsed_route(record)
    assert all(same(getattr(direct, f.name), getattr(parsed, f.name))
               for f in dataclasses.fields(direct))
