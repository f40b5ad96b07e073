"""calib.json read again: the schema check is made once per content (a mark in the user's
cache folder), every other check at every read."""

from __future__ import annotations

import json

import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.errors import ModelError
from olp_compensate.io import calibration_file
from olp_compensate.io.calibration_file import read_calibration, write_calibration
from olp_compensate.kinematics.robot import load_robot


@pytest.fixture()
def checks(monkeypatch):
    """How many times a document was checked against the schema."""
    real = calibration_file._validator
    count = {"n": 0}

    def counted():
        count["n"] += 1
        return real()

    monkeypatch.setattr(calibration_file, "_validator", counted)
    return count


@pytest.fixture()
def calib(tmp_path):
    path = tmp_path / "calib.json"
    write_calibration(path, nominal_calibration(load_robot("abb_irb2400")))
    return path


def test_a_valid_file_is_checked_against_the_schema_once(tmp_path, monkeypatch, checks, calib):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    first = read_calibration(calib)
    assert checks["n"] == 1
    second = read_calibration(calib)
    assert checks["n"] == 1
    write_calibration(tmp_path / "a.json", first)
    write_calibration(tmp_path / "b.json", second)
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_changed_bytes_are_checked_again(tmp_path, monkeypatch, checks, calib):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    read_calibration(calib)
    doc = json.loads(calib.read_text())
    doc["robot"]["fingerprint"] = 12
    calib.write_text(json.dumps(doc))
    with pytest.raises(ModelError, match="invalid calibration at robot/fingerprint"):
        read_calibration(calib)
    assert checks["n"] == 2


def test_a_file_that_fails_a_later_check_is_not_marked(tmp_path, monkeypatch, checks, calib):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    doc = json.loads(calib.read_text())
    doc["robot"]["fingerprint"] = "sha256:" + "0" * 64     # valid for the schema only
    calib.write_text(json.dumps(doc))
    for expected_checks in (1, 2):
        with pytest.raises(ModelError, match="does not match the stored fingerprint"):
            read_calibration(calib)
        assert checks["n"] == expected_checks


def test_without_a_cache_folder_every_read_is_checked(monkeypatch, checks, calib):
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")
    read_calibration(calib)
    read_calibration(calib)
    assert checks["n"] == 2
