"""The stand-in checker itself: it must catch each way a stand-in can drift from the real object."""

from __future__ import annotations

import types

from tests.standins import _docstring_signature, check_standin, stands_in_for


def test_a_faithful_standin_passes():
    @stands_in_for("json:JSONDecoder")
    class Decoder:
        def decode(self, s):
            return {}

        def raw_decode(self, s, idx=0):
            return {}, idx

    assert check_standin(Decoder) == []


def test_each_kind_of_drift_is_reported():
    @stands_in_for("json:JSONDecoder", attributes=("no_such_attribute",))
    class Drifted:
        def decode(self):  # the real one requires the text
            return {}

        def raw_decode(self, s, idx=0, extra=None):  # the real one takes no third argument
            return {}, idx

        def parse(self, s):  # the real one has no such method
            return {}

    problems = check_standin(Drifted)
    assert len(problems) == 5, problems
    assert "decode: the stand-in accepts 0 positional and [] keyword arguments, the real (s, _w=" in problems[0]
    assert "decode: the real (s, _w=" in problems[1] and "requires 1 arguments, the stand-in () only 0" in problems[1]
    assert "raw_decode: the stand-in accepts 3 positional" in problems[2]
    assert problems[3].endswith("the real object has no 'parse'")
    assert problems[4].endswith("the real object has no attribute 'no_such_attribute'")


def test_module_constants_are_compared():
    @stands_in_for("math")
    class FakeMath:
        pi = 3.0

    assert check_standin(FakeMath) == ["FakeMath (for math): pi is 3.0, the real one 3.141592653589793"]


def test_signatures_of_c_extensions_come_from_their_docstrings():
    swig = types.SimpleNamespace(__doc__="capture(self, type, context)\n\nParameters\n----------\n"
                                         "type: CameraCaptureType\ncontext: gphoto2.Context (default=None)\n")
    assert str(_docstring_signature(swig)) == "(self, type, context=None)"
    opencv = types.SimpleNamespace(__doc__="open(filename, apiPreference[, params]) -> retval\n.   @brief Opens")
    assert str(_docstring_signature(opencv)) == "(filename, apiPreference, params=None)"
