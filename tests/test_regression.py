"""A refactor changes no number: representative traces, solves and robot runs against the
fingerprints recorded before the package was split into layers (tests/regression.py)."""

import json

import pytest

from regression import CASES, DATA, compare


@pytest.mark.parametrize("name", sorted(CASES))
def test_fingerprint_unchanged(name):
    expected = json.loads(DATA.read_text())[name]
    assert compare(expected, CASES[name]()) == []
