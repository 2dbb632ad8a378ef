import math
import numbers
import re

import numpy as np
import pytest
from sklearn.base import BaseEstimator

from eppf.utils._param_validation import (
    IntTuple,
    InvalidParameterError,
    Interval,
    Options,
    Satisfies,
    StrOptions,
    make_constraint,
    validate_parameter,
    validate_params,
)

INT_GE_1 = Interval(numbers.Integral, 1, None, closed="left")


# ------------------------------------------------------------------ Interval
@pytest.mark.parametrize(
    "closed, left_in, right_in, text",
    [
        ("left", True, False, "a float in [0.0, 1.0)"),
        ("right", False, True, "a float in (0.0, 1.0]"),
        ("both", True, True, "a float in [0.0, 1.0]"),
        ("neither", False, False, "a float in (0.0, 1.0)"),
    ],
)
def test_real_interval_bounds(closed, left_in, right_in, text):
    c = Interval(numbers.Real, 0, 1, closed=closed)
    assert c.is_satisfied_by(0) is left_in and c.is_satisfied_by(0.0) is left_in
    assert c.is_satisfied_by(1.0) is right_in
    assert c.is_satisfied_by(0.5) and c.is_satisfied_by(np.float32(0.5))
    assert not c.is_satisfied_by(-1e-300) and not c.is_satisfied_by(1 + 1e-15)
    assert str(c) == text


def test_real_interval_rejects_non_numbers_nan_inf_and_bool():
    c = Interval(numbers.Real, None, None, closed="neither")
    assert str(c) == "a float in (-inf, inf)"
    assert c.is_satisfied_by(-1e308) and c.is_satisfied_by(5e-324)
    for bad in (math.nan, math.inf, -math.inf, np.float64("nan"), True, np.bool_(False), "1", None, 1j, [1.0]):
        assert not c.is_satisfied_by(bad), bad


def test_integral_interval():
    assert str(INT_GE_1) == "an int >= 1"
    assert INT_GE_1.is_satisfied_by(1) and INT_GE_1.is_satisfied_by(np.int64(7)) and INT_GE_1.is_satisfied_by(2**70)
    for bad in (0, -3, 1.0, 1.5, True, np.bool_(True), "2", None):
        assert not INT_GE_1.is_satisfied_by(bad), bad
    gt = Interval(numbers.Integral, 1, None, closed="neither")
    assert str(gt) == "an int > 1" and not gt.is_satisfied_by(1) and gt.is_satisfied_by(2)
    le = Interval(numbers.Integral, None, -1, closed="right")
    assert str(le) == "an int <= -1" and le.is_satisfied_by(-1) and not le.is_satisfied_by(0)
    both = Interval(numbers.Integral, 0, 9, closed="both")
    assert str(both) == "an int in [0, 9]" and both.is_satisfied_by(9) and not both.is_satisfied_by(10)
    assert str(Interval(numbers.Integral, None, None, closed="neither")) == "an int"


@pytest.mark.parametrize(
    "args, kwargs, err, msg",
    [
        ((int, 0, 1), {"closed": "both"}, TypeError, "Interval: type must be numbers.Integral or numbers.Real"),
        ((numbers.Real, 0, 1), {"closed": "open"}, ValueError, "Interval: closed must be one of"),
        ((numbers.Real, 2, 1), {"closed": "both"}, ValueError, "Interval: left=2 is greater than right=1"),
        ((numbers.Real, math.nan, 1), {"closed": "both"}, TypeError, "Interval: left must be a finite number or None"),
        ((numbers.Real, 0, "1"), {"closed": "both"}, TypeError, "Interval: right must be a finite number or None"),
    ],
)
def test_interval_rejects_bad_definitions(args, kwargs, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        Interval(*args, **kwargs)


# ------------------------------------------------------------------- Options
def test_str_options_order_and_type():
    listed = StrOptions(["4d", "3d", "2d"])
    assert str(listed) == "one of '4d', '3d', '2d'"  # a list keeps its order
    assert str(StrOptions({"plateau", "constant"})) == "'constant' or 'plateau'"  # a set is sorted
    assert str(StrOptions({"z"})) == "'z'"
    assert listed.is_satisfied_by("3d") and not listed.is_satisfied_by("5d")
    assert not listed.is_satisfied_by(b"4d") and not listed.is_satisfied_by(None) and not listed.is_satisfied_by(4)
    with pytest.raises(TypeError, match="not the str 'abc'"):
        StrOptions("abc")
    with pytest.raises(TypeError, match="every option must be a str"):
        StrOptions(["a", 1])
    with pytest.raises(ValueError, match="values must not be empty"):
        StrOptions([])


def test_options_bool_and_types():
    c = Options(bool)
    assert str(c) == "True or False"
    assert c.is_satisfied_by(True) and c.is_satisfied_by(np.bool_(False))
    for bad in (0, 1, "True", None, 1.0):
        assert not c.is_satisfied_by(bad), bad
    ints = Options(int)
    assert str(ints) == "an int"
    assert ints.is_satisfied_by(3) and not ints.is_satisfied_by(True)  # bool is not an int here
    strs = Options(str, description="a str such as 'cpu' or 'cuda'")
    assert str(strs) == "a str such as 'cpu' or 'cuda'" and strs.is_satisfied_by("cpu") and not strs.is_satisfied_by(0)
    vals = Options(float, {math.inf})
    assert str(vals) == "inf" and vals.is_satisfied_by(math.inf) and not vals.is_satisfied_by(1.0)
    assert Options((str, bytes)).is_satisfied_by(b"x") and str(Options((str, bytes))) == "a str or a bytes"
    with pytest.raises(TypeError, match="Options: type must be a type or a tuple of types"):
        Options("bool")


def test_int_tuple_unbounded_above():
    c = IntTuple(3, 1, None)
    assert c.is_satisfied_by((1, 2, 10**9)) and c.is_satisfied_by(np.array([4, 5, 6]))
    assert not c.is_satisfied_by((0, 2, 3))  # below left
    assert not c.is_satisfied_by((1, 2))  # wrong length
    assert not c.is_satisfied_by((1, 2, 3.0)) and not c.is_satisfied_by((1, True, 3))  # not ints
    assert not c.is_satisfied_by("123")
    assert str(c) == "a tuple of 3 ints >= 1"
    with pytest.raises(TypeError, match="left must be an int"):
        IntTuple(3, None, 5)


def test_satisfies():
    c = Satisfies(lambda v: len(v) == 3, "a sequence of 3")
    assert c.is_satisfied_by((1, 2, 3)) and not c.is_satisfied_by((1, 2))
    assert not c.is_satisfied_by(5)  # the predicate raises TypeError: counts as not accepted
    assert str(c) == "a sequence of 3"
    with pytest.raises(TypeError, match="predicate must be callable"):
        Satisfies(3, "x")
    with pytest.raises(TypeError, match="description must be a str"):
        Satisfies(bool, None)


def test_make_constraint():
    assert make_constraint(None).is_satisfied_by(None) and not make_constraint(None).is_satisfied_by(0)
    assert str(make_constraint(None)) == "None"
    anything = make_constraint("no_validation")
    assert anything.is_satisfied_by(object()) and anything.is_satisfied_by(None)
    assert make_constraint(INT_GE_1) is INT_GE_1
    for bad in ("boolean", int, 3):
        with pytest.raises(TypeError, match="unknown parameter constraint"):
            make_constraint(bad)


# ---------------------------------------------------------- validate_parameter
def test_validate_parameter_messages():
    assert validate_parameter(3, [INT_GE_1], name="n", owner="f") == 3
    with pytest.raises(InvalidParameterError, match=re.escape("f: n must be an int >= 1, got 0")):
        validate_parameter(0, [INT_GE_1], name="n", owner="f")
    both = [None, Interval(numbers.Real, 0, None, closed="neither")]
    assert validate_parameter(None, both, name="t", owner="g") is None
    with pytest.raises(InvalidParameterError, match=re.escape("g: t must be None or a float in (0.0, inf), got '1h'")):
        validate_parameter("1h", both, name="t", owner="g")
    rot = [StrOptions(["z"]), None]
    with pytest.raises(InvalidParameterError, match=re.escape("h: r must be 'z' or None, got 'y'")):
        validate_parameter("y", rot, name="r", owner="h")


def test_invalid_parameter_error_is_value_and_type_error():
    for cls in (ValueError, TypeError):
        with pytest.raises(cls):
            validate_parameter("x", [INT_GE_1], name="n", owner="f")


def test_validate_parameter_rejects_bad_constraint_lists():
    with pytest.raises(TypeError, match="the constraints of n must be a list"):
        validate_parameter(1, INT_GE_1, name="n", owner="f")
    with pytest.raises(TypeError, match="the constraint list of n is empty"):
        validate_parameter(1, [], name="n", owner="f")


# ------------------------------------------------------------ validate_params
class _Toy(BaseEstimator):
    _parameter_constraints = {
        "n": [INT_GE_1],
        "mode": [StrOptions(["fast", "exact"])],
        "flag": [Options(bool)],
        "extra": ["no_validation"],
    }

    def __init__(self, n=1, mode="fast", flag=False, extra=None):
        self.n = n
        self.mode = mode
        self.flag = flag
        self.extra = extra


def test_validate_params_names_estimator_and_parameter():
    validate_params(_Toy(n=5, mode="exact", flag=True, extra=object()))
    with pytest.raises(InvalidParameterError, match=re.escape("_Toy: mode must be 'fast' or 'exact', got 'slow'")):
        validate_params(_Toy(mode="slow"))
    with pytest.raises(InvalidParameterError, match=re.escape("_Toy: flag must be True or False, got 1")):
        validate_params(_Toy(flag=1))
    with pytest.raises(InvalidParameterError, match=re.escape("_Toy: n must be an int >= 1, got 2.0")):
        validate_params(_Toy(n=2.0))


def test_validate_params_requires_every_parameter():
    class Missing(_Toy):
        _parameter_constraints = {"n": [INT_GE_1]}

    with pytest.raises(TypeError, match=re.escape("Missing: _parameter_constraints has no entry for extra, flag, mode")):
        validate_params(Missing())

    class NoDict(BaseEstimator):
        pass

    with pytest.raises(TypeError, match="NoDict: the class declares no _parameter_constraints dict"):
        validate_params(NoDict())


def test_classifiers_declare_every_parameter():
    from eppf import EPPF4DClassifier, PointNetClassifier

    for est in (EPPF4DClassifier(), PointNetClassifier()):
        assert set(type(est)._parameter_constraints) == set(est.get_params(deep=False))
        validate_params(est)  # the defaults are valid
