"""Declarative validation of estimator parameters.

An estimator lists, for every parameter of its ``__init__``, the values it
accepts, in a class attribute ``_parameter_constraints``::

    _parameter_constraints = {
        "max_epochs": [Interval(numbers.Integral, 1, None, closed="left")],
        "lr": [Interval(numbers.Real, 0, None, closed="neither")],
        "conv": [StrOptions(["4d", "3d", "2d"])],
        "early_stopping": [Options(bool)],
        "max_time": [None, Interval(numbers.Real, 0, None, closed="neither")],
        "device": [Options(str, description="a str such as 'cpu' or 'cuda'")],
        "n_jobs": N_JOBS,
        "callback": ["no_validation"],
    }

and calls :func:`validate_params` once at the start of ``fit``. A value is
accepted when it satisfies at least one constraint of its list. Otherwise an
:class:`InvalidParameterError` names the estimator, the parameter, what is
accepted and the value received, e.g. ``"EPPF4DClassifier: max_epochs must be
an int >= 1, got 0"``.

Constraints
-----------
``None``
    The value ``None``.
``Interval(type, left, right, closed=...)``
    A number of ``type`` (:class:`numbers.Integral` or :class:`numbers.Real`)
    between ``left`` and ``right`` (None: unbounded on that side), ``closed``
    one of ``"left"``, ``"right"``, ``"both"``, ``"neither"``. bool is never
    a number here. A Real interval takes ints and floats but never NaN and
    never an infinity (an unbounded side is open).
``StrOptions(options)``
    One of the given strings (a set is listed sorted in messages, a list or
    tuple in its own order).
``Options(type, values=None, description=None)``
    An instance of ``type`` (``Options(bool)`` also takes ``numpy.bool_``),
    restricted to ``values`` when given.
``IntTuple(length, left, right, max_product=None)``
    A sequence (not a str) of ``length`` ints in ``[left, right]`` (right
    None: unbounded), e.g. the
    bin counts of a histogram's axes, optionally with at most
    ``max_product`` cells in all.
``Satisfies(predicate, description)``
    Any value for which ``predicate(value)`` is true; for the rare
    parameter that the others cannot describe (a non-zero int).
``"no_validation"``
    Anything; the parameter is checked elsewhere.

Every constraint has an optional ``description`` that replaces the generated
one in messages. Constraint lists are data, so documentation and tests can
read them; this module imports nothing from eppf.
"""

import builtins
import math
import numbers

import numpy as np

__all__ = [
    "N_JOBS",
    "RANDOM_STATE",
    "IntTuple",
    "InvalidParameterError",
    "Interval",
    "Options",
    "Satisfies",
    "StrOptions",
    "make_constraint",
    "validate_parameter",
    "validate_params",
]


class InvalidParameterError(ValueError, TypeError):
    """A parameter's value is not one of those its constraints accept.

    Subclasses both ValueError and TypeError (as scikit-learn's error of the
    same name), so callers catching either see it: a wrong type and a value
    out of range are told apart by the message, not by the class.
    """


class _Constraint:
    """Base of the constraints: ``is_satisfied_by`` and a description."""

    def __init__(self, description=None):
        if description is not None and not isinstance(description, str):
            raise TypeError(f"{type(self).__name__}: description must be a str or None, got {description!r}")
        self.description = description

    def is_satisfied_by(self, value):  # pragma: no cover - abstract
        raise NotImplementedError

    def _describe(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def __str__(self):
        return self.description if self.description is not None else self._describe()


class _NoneConstraint(_Constraint):
    def is_satisfied_by(self, value):
        return value is None

    def _describe(self):
        return "None"


def _is_int(value):
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def _is_real(value):
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


class Interval(_Constraint):
    """Numbers of a type within an interval.

    Parameters
    ----------
    type : {numbers.Integral, numbers.Real}
        Integral accepts ints (Python and NumPy, not bool); Real accepts any
        real number except bool, NaN and infinities.
    left, right : number or None
        Bounds; None leaves that side unbounded.
    closed : {"left", "right", "both", "neither"}
        Which bounds belong to the interval.
    description : str, default=None
        Replaces the generated description in messages.

    Examples
    --------
    >>> import numbers
    >>> from eppf.utils._param_validation import Interval
    >>> c = Interval(numbers.Real, 0, 1, closed="left")
    >>> c.is_satisfied_by(0), c.is_satisfied_by(1.0), str(c)
    (True, False, 'a float in [0.0, 1.0)')
    """

    _CLOSED = ("left", "right", "both", "neither")

    def __init__(self, type, left, right, *, closed, description=None):
        super().__init__(description)
        if type not in (numbers.Integral, numbers.Real):
            raise TypeError(f"Interval: type must be numbers.Integral or numbers.Real, got {type!r}")
        if closed not in self._CLOSED:
            raise ValueError(f"Interval: closed must be one of {self._CLOSED}, got {closed!r}")
        for side, bound in (("left", left), ("right", right)):
            if bound is not None and not (_is_real(bound) and math.isfinite(bound)):
                raise TypeError(f"Interval: {side} must be a finite number or None, got {bound!r}")
        if left is not None and right is not None and left > right:
            raise ValueError(f"Interval: left={left!r} is greater than right={right!r}")
        self.type = type
        self.left = left
        self.right = right
        self.closed = closed

    def is_satisfied_by(self, value):
        if self.type is numbers.Integral:
            if not _is_int(value):
                return False
        elif not (_is_real(value) and math.isfinite(value)):
            return False
        left_closed = self.closed in ("left", "both")
        right_closed = self.closed in ("right", "both")
        if self.left is not None and not (value >= self.left if left_closed else value > self.left):
            return False
        if self.right is not None and not (value <= self.right if right_closed else value < self.right):
            return False
        return True

    def _describe(self):
        left_closed = self.closed in ("left", "both")
        right_closed = self.closed in ("right", "both")
        if self.type is numbers.Integral:
            if self.left is not None and self.right is None:
                return f"an int {'>=' if left_closed else '>'} {self.left}"
            if self.left is None and self.right is not None:
                return f"an int {'<=' if right_closed else '<'} {self.right}"
            if self.left is None and self.right is None:
                return "an int"
            kind, fmt = "an int", int
        else:
            kind, fmt = "a float", float
        lo = "-inf" if self.left is None else fmt(self.left)
        hi = "inf" if self.right is None else fmt(self.right)
        return f"{kind} in {'[' if left_closed else '('}{lo}, {hi}{']' if right_closed else ')'}"


def _listed(options, last="or"):
    """``'a'``, ``'a' or 'b'``, ``one of 'a', 'b', 'c'``."""
    reprs = [repr(o) for o in options]
    if len(reprs) == 1:
        return reprs[0]
    if len(reprs) == 2:
        return f"{reprs[0]} {last} {reprs[1]}"
    return "one of " + ", ".join(reprs)


class Options(_Constraint):
    """Instances of a type, optionally one of given values.

    Parameters
    ----------
    type : type or tuple of types
        Accepted type(s). ``bool`` also accepts ``numpy.bool_``.
    values : iterable, default=None
        When given, only these values (compared with ``==`` after the type
        test) are accepted.
    description : str, default=None
        Replaces the generated description in messages.

    Examples
    --------
    >>> from eppf.utils._param_validation import Options
    >>> c = Options(bool)
    >>> c.is_satisfied_by(True), c.is_satisfied_by(1), str(c)
    (True, False, 'True or False')
    """

    def __init__(self, type, values=None, *, description=None):
        super().__init__(description)
        types = type if isinstance(type, tuple) else (type,)
        if not types or not all(isinstance(t, builtins.type) for t in types):
            raise TypeError(f"Options: type must be a type or a tuple of types, got {type!r}")
        if bool in types:
            types = types + (np.bool_,)
        self.type = type
        self._types = types
        if values is not None:
            values = sorted(values, key=repr) if isinstance(values, (set, frozenset)) else list(values)
            if not values:
                raise ValueError("Options: values must not be empty")
        self.values = values

    def is_satisfied_by(self, value):
        if not isinstance(value, self._types):
            return False
        if bool not in self._types and isinstance(value, (bool, np.bool_)):
            # bool is an int subclass: Options(int) means a true int.
            return False
        if self.values is None:
            return True
        return any(value == v for v in self.values)

    def _describe(self):
        if self.values is not None:
            return _listed(self.values)
        if self.type is bool:
            return "True or False"
        names = [t.__name__ for t in (self.type if isinstance(self.type, tuple) else (self.type,))]
        return " or ".join(("an " if n[0].lower() in "aeiou" else "a ") + n for n in names)


class StrOptions(Options):
    """One of a fixed set of strings.

    Parameters
    ----------
    options : iterable of str
        Accepted strings; a set is listed sorted in messages, a list or a
        tuple in its own order.
    description : str, default=None
        Replaces the generated description in messages.

    Examples
    --------
    >>> from eppf.utils._param_validation import StrOptions
    >>> c = StrOptions(["constant", "plateau"])
    >>> c.is_satisfied_by("plateau"), str(c)
    (True, "'constant' or 'plateau'")
    """

    def __init__(self, options, *, description=None):
        if isinstance(options, str):
            raise TypeError(f"StrOptions: options must be an iterable of str, not the str {options!r}")
        options = sorted(options) if isinstance(options, (set, frozenset)) else list(options)
        if not all(isinstance(o, str) for o in options):
            raise TypeError(f"StrOptions: every option must be a str, got {options!r}")
        super().__init__(str, options, description=description)


class IntTuple(_Constraint):
    """A fixed-length sequence of ints within bounds (bin counts per axis).

    Parameters
    ----------
    length : int
        Number of entries.
    left, right : int or None
        Bounds of every entry, both included; ``right=None`` leaves the
        entries unbounded above.
    max_product : int, default=None
        Largest accepted product of the entries (the number of cells).
    description : str, default=None
        Replaces the generated description in messages.

    Examples
    --------
    >>> from eppf.utils._param_validation import IntTuple
    >>> c = IntTuple(4, 1, 64)
    >>> c.is_satisfied_by((20, 4, 5, 3)), c.is_satisfied_by((20, 4, 5)), str(c)
    (True, False, 'a tuple of 4 ints in [1, 64]')
    """

    def __init__(self, length, left, right, *, max_product=None, description=None):
        super().__init__(description)
        for name, v in (("length", length), ("left", left), ("right", right)):
            if not _is_int(v) and not (name == "right" and v is None):
                raise TypeError(f"IntTuple: {name} must be an int, got {v!r}")
        if length < 1 or (right is not None and left > right):
            raise ValueError(f"IntTuple: need length >= 1 and left <= right, got {length}, {left}, {right}")
        if max_product is not None and not _is_int(max_product):
            raise TypeError(f"IntTuple: max_product must be an int or None, got {max_product!r}")
        self.length = int(length)
        self.left = int(left)
        self.right = None if right is None else int(right)
        self.max_product = max_product

    def is_satisfied_by(self, value):
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            return False
        try:
            values = tuple(value)
        except TypeError:
            return False
        if len(values) != self.length or not all(
            _is_int(v) and self.left <= v and (self.right is None or v <= self.right) for v in values
        ):
            return False
        return self.max_product is None or math.prod(int(v) for v in values) <= self.max_product

    def _describe(self):
        if self.right is None:
            out = f"a tuple of {self.length} ints >= {self.left}"
        else:
            out = f"a tuple of {self.length} ints in [{self.left}, {self.right}]"
        if self.max_product is not None:
            out += f" with a product of at most {self.max_product}"
        return out


class Satisfies(_Constraint):
    """Any value for which a predicate holds.

    Parameters
    ----------
    predicate : callable
        ``predicate(value)`` returns true for accepted values; an exception
        it raises counts as "not accepted".
    description : str
        What the predicate accepts, for messages (e.g. "a tuple of 3
        positive ints").

    Examples
    --------
    >>> from eppf.utils._param_validation import Satisfies
    >>> c = Satisfies(lambda v: v != 0, "anything but 0")
    >>> c.is_satisfied_by(3), str(c)
    (True, 'anything but 0')
    """

    def __init__(self, predicate, description):
        if not callable(predicate):
            raise TypeError(f"Satisfies: predicate must be callable, got {predicate!r}")
        if not isinstance(description, str):
            raise TypeError(f"Satisfies: description must be a str, got {description!r}")
        super().__init__(description)
        self.predicate = predicate

    def is_satisfied_by(self, value):
        try:
            return bool(self.predicate(value))
        except Exception:
            return False


class _NoValidation(_Constraint):
    def is_satisfied_by(self, value):
        return True

    def _describe(self):
        return "anything"


def make_constraint(constraint):
    """Turn one entry of a constraint list into a constraint object.

    Parameters
    ----------
    constraint : None, "no_validation" or constraint object
        ``None`` accepts the value None; ``"no_validation"`` accepts anything.

    Returns
    -------
    constraint : constraint object
    """
    if constraint is None:
        return _NoneConstraint()
    if isinstance(constraint, str) and constraint == "no_validation":
        return _NoValidation()
    if isinstance(constraint, _Constraint):
        return constraint
    raise TypeError(f"unknown parameter constraint {constraint!r}; use None, 'no_validation' or a constraint object")


def validate_parameter(value, constraints, *, name, owner):
    """Check one value against a list of constraints.

    Parameters
    ----------
    value : object
        The value to check.
    constraints : list
        Constraints as in ``_parameter_constraints``; the value must satisfy
        at least one.
    name : str
        Parameter name, for the message.
    owner : str
        Estimator or function name, for the message.

    Returns
    -------
    value : object
        ``value`` unchanged.

    Raises
    ------
    InvalidParameterError
        When no constraint accepts the value.

    Examples
    --------
    >>> import numbers
    >>> from eppf.utils._param_validation import Interval, validate_parameter
    >>> validate_parameter(0, [Interval(numbers.Integral, 1, None, closed="left")],
    ...                    name="n_pairs", owner="f")
    Traceback (most recent call last):
    ...
    eppf.utils._param_validation.InvalidParameterError: f: n_pairs must be an int >= 1, got 0
    """
    if isinstance(constraints, (str, _Constraint)) or constraints is None:
        raise TypeError(f"{owner}: the constraints of {name} must be a list, got {constraints!r}")
    made = [make_constraint(c) for c in constraints]
    if not made:
        raise TypeError(f"{owner}: the constraint list of {name} is empty")
    if any(c.is_satisfied_by(value) for c in made):
        return value
    accepted = " or ".join(str(c) for c in made)
    raise InvalidParameterError(f"{owner}: {name} must be {accepted}, got {value!r}")


def validate_params(estimator):
    """Check every parameter of an estimator against its ``_parameter_constraints``.

    Parameters
    ----------
    estimator : BaseEstimator
        Its class has a dict ``_parameter_constraints`` with an entry for
        every parameter of ``get_params(deep=False)``.

    Raises
    ------
    InvalidParameterError
        For the first parameter (in ``get_params`` order) no constraint of
        which accepts its value; the message names the estimator's class.
    TypeError
        When the class declares no constraints, or some parameter has no
        entry (a developer error, caught by the tests).
    """
    owner = type(estimator).__name__
    declared = getattr(type(estimator), "_parameter_constraints", None)
    if not isinstance(declared, dict):
        raise TypeError(f"{owner}: the class declares no _parameter_constraints dict")
    params = estimator.get_params(deep=False)
    missing = sorted(set(params) - set(declared))
    if missing:
        raise TypeError(f"{owner}: _parameter_constraints has no entry for {', '.join(missing)}")
    for name, value in params.items():
        validate_parameter(value, declared[name], name=name, owner=owner)


def _nonzero_int(value):
    return _is_int(value) and value != 0


#: ``n_jobs``: None (OpenMP's default) or joblib's non-zero ints.
N_JOBS = [None, Satisfies(_nonzero_int, "a non-zero int (-1: all cores)")]
#: ``random_state``: what :func:`sklearn.utils.check_random_state` takes.
RANDOM_STATE = [
    None,
    Interval(numbers.Integral, 0, 2**32 - 1, closed="both"),
    Options(np.random.RandomState, description="a numpy RandomState"),
]
