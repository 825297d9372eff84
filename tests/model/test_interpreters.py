"""Finding Python interpreters (core/model/interpreters.py): version ranges, probing real ones."""

from __future__ import annotations

import os
import stat
import sys

import pytest

from artgs.core.model import interpreters


def test_requires_python_ranges():
    assert interpreters.parse_requires(">=3.11,<3.12") == ((3, 11), (3, 12))
    assert interpreters.parse_requires(">=3.11") == ((3, 11), None)
    assert interpreters.matches((3, 11, 7), (3, 11), (3, 12))
    assert not interpreters.matches((3, 12, 0), (3, 11), (3, 12))
    assert not interpreters.matches((3, 10, 9), (3, 11), None)
    with pytest.raises(ValueError, match="only '>=X.Y' and '<X.Y'"):
        interpreters.parse_requires("~=3.11")


def test_finds_this_python_and_skips_what_does_not_run(tmp_path):
    me = tuple(sys.version_info[:3])
    broken = tmp_path / "python3.99"  # a shim that fails, as an inactive pyenv shim does
    broken.write_text("#!/bin/sh\necho 'pyenv: python3.99: command not found' >&2\nexit 127\n")
    broken.chmod(broken.stat().st_mode | stat.S_IEXEC)
    assert interpreters.probe(broken) is None
    found = interpreters.find(me[:2], (me[0], me[1] + 1), extra=[str(broken), sys.executable])
    assert found and found[0].version == me
    assert os.path.realpath(found[0].path) == os.path.realpath(sys.executable)
    assert len({os.path.realpath(i.path) for i in found}) == len(found)  # each Python once
    assert interpreters.find((3, 99), (3, 100), extra=[sys.executable]) == []
