"""One-line checks on user values: each error names the key and the allowed range."""

from __future__ import annotations

import math
import numbers

from forward.errors import SceneError

MAX_DEPTH = 32  # levels of tables and arrays in a scene; the examples use 6
MAX_EXPRESSION_LENGTH = 200  # characters of one numeric expression
SEED_RANGE = "[0, 2^32)"


def one_line(text: object, limit: int = 120) -> str:
    """`text` for an error message: on one line (characters that are not printable, line breaks
    among them, are escaped) and at most about `limit` characters."""
    s = str(text)
    if len(s) > limit:
        s = s[: limit - 3] + "..."
    if s.isprintable():
        return s
    return "".join(c if c.isprintable() else c.encode("unicode_escape", "backslashreplace").decode("ascii") for c in s)


def check_depth(value: object, key: str = "") -> None:
    """SceneError when tables (dicts) and arrays (lists) nest deeper than MAX_DEPTH levels, the
    table itself being level 1. Iterative, so that neither a deep nor a cyclic table can exhaust
    the interpreter's recursion limit here or in the code that walks the table later."""
    stack = [(value, key, 1)]
    while stack:
        node, path, depth = stack.pop()
        if isinstance(node, dict):
            items = ((f"{path}.{k}" if path else str(k), v) for k, v in node.items())
        elif isinstance(node, list):
            items = ((f"{path}[{i}]", v) for i, v in enumerate(node))
        else:
            continue
        if depth > MAX_DEPTH:
            raise SceneError(
                f"{one_line(path or 'scene')}: nesting deeper than {MAX_DEPTH} levels of tables and arrays; "
                f"allowed at most {MAX_DEPTH}"
            )
        stack.extend((v, p, depth + 1) for p, v in items if isinstance(v, (dict, list)))


def seed(value: object, key: str = "seed") -> int | None:
    """A random seed: None or an integer in [0, 2^32), else SceneError."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise SceneError(f"{key}: must be an integer in the allowed range {SEED_RANGE}, got {one_line(repr(value))}")
    v = int(value)
    if not 0 <= v < 2**32:
        raise SceneError(f"{key}: {v} is outside the allowed range {SEED_RANGE}")
    return v


def number(
    value: object, key: str, lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False, hi_open: bool = False
) -> float:
    """`value` as a finite float in the interval [lo, hi] (ends open when asked), else SceneError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{key}: must be a finite number, got {one_line(repr(value))}")
    v = float(value)
    below = v <= lo if lo_open else v < lo
    above = v >= hi if hi_open else v > hi
    if below or above:
        raise SceneError(f"{key}: {v:g} is outside the allowed range {interval(lo, hi, lo_open, hi_open)}")
    return v


def integer(value: object, key: str, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi], else SceneError."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(f"{key}: must be an integer, got {one_line(repr(value))}")
    if not lo <= value <= hi:
        raise SceneError(f"{key}: {value} is outside the allowed range [{lo}, {hi}]")
    return value


def interval(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False) -> str:
    """Human-readable interval, e.g. (0, pi/2]."""

    def fmt(v: float) -> str:
        for name, ref in (("pi/2", math.pi / 2), ("pi", math.pi), ("2 pi", 2 * math.pi)):
            if v == ref:
                return name
        return "inf" if v == math.inf else "-inf" if v == -math.inf else f"{v:g}"

    return f"{'(' if lo_open else '['}{fmt(lo)}, {fmt(hi)}{')' if hi_open else ']'}"


_FUNCTIONS = {
    "sqrt": math.sqrt,
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "arcsin": math.asin,
    "arccos": math.acos,
    "arctan": math.atan,
    "atan2": math.atan2,
    "radians": math.radians,
    "exp": math.exp,
    "log": math.log,
    "log10": math.log10,
}
_CONSTANTS = {"pi": math.pi, "e": math.e}


def expression(text: str, key: str) -> float:
    """Evaluate a numeric expression such as "pi/3 + 0.015" or "arctan(1.5)" (no names but
    pi, e and the functions sqrt, sin, cos, tan, arcsin, arccos, arctan, atan2, radians, exp, log,
    log10) to a finite float.

    At most MAX_EXPRESSION_LENGTH characters (surrounding blanks aside), which bounds the parse and
    the evaluation: every constant is read as a float, so each operation, a power with a huge
    exponent included, costs O(1) and overflows (an error) instead of growing.
    """
    import ast
    import operator

    text = text.strip()
    if len(text) > MAX_EXPRESSION_LENGTH:
        raise SceneError(
            f"{key}: an expression of {len(text)} characters; allowed at most {MAX_EXPRESSION_LENGTH} characters"
        )

    ops = {
        ast.Add: operator.add,
        ast.Sub: operator.sub,
        ast.Mult: operator.mul,
        ast.Div: operator.truediv,
        ast.Pow: operator.pow,
        ast.USub: operator.neg,
        ast.UAdd: operator.pos,
    }

    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return float(node.value)
        if isinstance(node, ast.Name) and node.id in _CONSTANTS:
            return _CONSTANTS[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in ops:
            return ops[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in ops:
            return ops[type(node.op)](ev(node.operand))
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in _FUNCTIONS
            and not node.keywords
        ):
            return _FUNCTIONS[node.func.id](*(ev(a) for a in node.args))
        raise ValueError

    try:
        value = float(ev(ast.parse(text, mode="eval").body))
    except OverflowError:
        raise SceneError(
            f"{key}: {one_line(repr(text))} overflows float64 (|x| > 1.8e308); allowed: a finite number"
        ) from None
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, RecursionError, MemoryError):
        raise SceneError(
            f"{key}: {one_line(repr(text))} is not a number or a numeric expression (pi, sqrt, arctan, ...)"
        ) from None
    if not math.isfinite(value):
        raise SceneError(f"{key}: {one_line(repr(text))} evaluates to {value}; allowed: a finite number")
    return value


_REQUIRED = object()


class Table:
    """A scene table read key by key; `done()` rejects keys nobody asked for."""

    def __init__(self, data: object, key: str):
        if not isinstance(data, dict):
            raise SceneError(f"{key}: must be a table, got {one_line(repr(data))}")
        self.data, self.key, self.seen = data, key, set()

    def path(self, name: str) -> str:
        return one_line(f"{self.key}.{name}" if self.key else name)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: object = _REQUIRED) -> object:
        self.seen.add(name)
        if name in self.data:
            return self.data[name]
        if default is _REQUIRED:
            raise SceneError(f"{self.path(name)}: missing (required)")
        return default

    def number(
        self,
        name: str,
        default: object = _REQUIRED,
        lo: float = -math.inf,
        hi: float = math.inf,
        lo_open: bool = False,
        hi_open: bool = False,
    ) -> float:
        value = self.raw(name, default)
        if isinstance(value, str):
            value = expression(value, self.path(name))
        return number(value, self.path(name), lo, hi, lo_open, hi_open)

    def numbers(self, name: str, default: object = _REQUIRED, **bounds) -> list[float]:
        """A number or a list of numbers (each may be an expression), as a list."""
        value = self.raw(name, default)
        items = value if isinstance(value, list) else [value]
        sub = Table({f"{name}[{i}]": v for i, v in enumerate(items)}, self.key)
        return [sub.number(f"{name}[{i}]", **bounds) for i in range(len(items))]

    def integer(self, name: str, default: object, lo: int, hi: int) -> int:
        return integer(self.raw(name, default), self.path(name), lo, hi)

    def choice(self, name: str, default: object, allowed: tuple[str, ...]) -> str:
        value = self.raw(name, default)
        if value not in allowed:
            raise SceneError(f"{self.path(name)}: {one_line(repr(value))} is not one of {', '.join(allowed)}")
        return value

    def interval(self, name: str) -> tuple[float, float]:
        """[min, max] with min < max (a positive size)."""
        value = self.raw(name)
        key = self.path(name)
        if not (isinstance(value, list) and len(value) == 2):
            raise SceneError(f"{key}: must be [min, max] in m, got {one_line(repr(value))}")
        lo, hi = (expression(v, key) if isinstance(v, str) else number(v, key) for v in value)
        if not hi > lo:
            raise SceneError(f"{key}: [{lo:g}, {hi:g}] has size {hi - lo:g}; the allowed range is size > 0 (min < max)")
        return lo, hi

    def table(self, name: str, required: bool = True) -> Table | None:
        value = self.raw(name, _REQUIRED if required else None)
        return None if value is None else Table(value, self.path(name))

    def done(self) -> None:
        extra = [k for k in self.data if k not in self.seen]
        if extra:
            allowed = ", ".join(sorted(self.seen)) or "none"
            raise SceneError(f"{self.path(extra[0])}: unknown key; allowed here: {allowed}")
