"""One-line TypeErrors naming the argument (issue 60). When no signature of a C++ call accepts the arguments,
pybind11 raises "f(): incompatible function arguments. The following argument types are supported: ..." over several
lines, without saying which argument is wrong. install() wraps the calls of the extension module so that such an
error becomes "Scene.load: path must be a path (str or os.PathLike), got NoneType": the wrapper reads the signature
from pybind11's message and checks the arguments it was given against it, first mismatch first. Other errors, and
the calls' results, pass through unchanged."""

import functools
import operator
import os

_INCOMPATIBLE = ("incompatible function arguments", "incompatible constructor arguments")


def _split_top(text, sep=","):
    # Splits at `sep` outside brackets and quotes.
    out, depth, quote, cur = [], 0, None, ""
    for c in text:
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == sep and depth == 0:
            out.append(cur.strip())
            cur = ""
            continue
        cur += c
    if cur.strip():
        out.append(cur.strip())
    return out


def _signature(message):
    # The parameters (name, type, has_default) of the first signature listed in pybind11's message.
    for line in message.splitlines():
        line = line.strip()
        if line.startswith("1. ") and "(" in line:  # "1. (self: ..., x: int) -> T" or "1. hgs._hgs.T(x: int)"
            body = line[line.index("(") + 1:]
            depth, end = 1, None
            for i, c in enumerate(body):
                depth += c == "(" or c == "["
                depth -= c == ")" or c == "]"
                if depth == 0:
                    end = i
                    break
            params = []
            for p in _split_top(body[:end]):
                if p in ("*", "/") or ":" not in p:
                    continue
                name, rest = p.split(":", 1)
                typ = _split_top(rest, "=")[0].strip() if "=" in rest else rest.strip()
                params.append((name.strip(), typ, "=" in rest))
            return params
    return None


def _check(value, typ):
    # (matches, what is expected in words) for the pybind11 type `typ`.
    if typ.startswith("Optional["):
        ok, words = _check(value, typ[9:-1]) if value is not None else (True, "")
        return ok, words + " or None"
    if typ in ("object", "handle", "Any", "capsule"):
        return True, "anything"
    if typ in ("dict", "list", "tuple"):
        return isinstance(value, {"dict": dict, "list": list, "tuple": tuple}[typ]), "a " + typ
    if typ == "str":
        return isinstance(value, str), "a str"
    if typ == "bool":
        return isinstance(value, bool) or type(value).__name__ == "bool_", "a bool"
    if typ == "int":
        try:
            operator.index(value)
            return True, "an int"
        except TypeError:
            return False, "an int"
    if typ == "float":
        try:
            float(value)
            return not isinstance(value, (str, bytes)), "a number"
        except (TypeError, ValueError):
            return False, "a number"
    if typ == "os.PathLike":
        return isinstance(value, (str, os.PathLike)), "a path (str or os.PathLike)"
    for prefix, kinds in (("List[", (list, tuple)), ("Sequence[", (list, tuple)), ("Dict[", (dict,))):
        if typ.startswith(prefix):
            inner = _split_top(typ[len(prefix):-1])
            words = ("a dict" if kinds == (dict,) else "a list of " + inner[-1].replace("[", " [")) if inner else typ
            if not isinstance(value, kinds):
                return False, words
            items = value.items() if kinds == (dict,) else [(None, v) for v in value]
            for k, v in items:
                if (k is not None and not _check(k, inner[0])[0]) or not _check(v, inner[-1])[0]:
                    return False, words
            return True, words
    if typ.startswith("hgs._hgs."):
        cls = typ[len("hgs._hgs."):]
        return type(value).__name__ == cls.split(".")[-1] and cls.split(".")[0] in type(value).__module__ + "." + \
            type(value).__qualname__, "an hgs." + cls
    if typ.startswith("numpy.ndarray"):
        return True, "a numpy array"
    return True, typ


def _explain(where, message, args, kwargs, bound):
    params = _signature(message)
    if params is None:
        return None
    if bound and params and params[0][0] == "self":
        params = params[1:]
    given = dict(zip([p[0] for p in params], args))
    given.update(kwargs)
    for name, typ, _ in params:
        if name in given:
            ok, words = _check(given[name], typ)
            if not ok:
                return f"{where}: {name} must be {words}, got {type(given[name]).__name__}"
    unknown = [k for k in kwargs if k not in [p[0] for p in params]]
    if unknown:
        return f"{where}: unexpected argument '{unknown[0]}' (arguments: {', '.join(p[0] for p in params)})"
    missing = [p[0] for p in params[len(args):] if not p[2] and p[0] not in kwargs]
    if missing:
        return f"{where}: missing argument '{missing[0]}'"
    if len(args) > len(params):
        return f"{where}: takes at most {len(params)} positional arguments, got {len(args)}"
    return None


def _wrap(fn, where, bound):
    @functools.wraps(fn)
    def call(*args, **kwargs):
        # The traceback keeps this frame: every error path drops the arguments first, among them an __init__'s
        # half-made instance (pybind11 crashes on a method call, even repr, of an instance whose constructor
        # failed; a debugger or pytest showing the frame's locals would call it).
        try:
            return fn(*args, **kwargs)
        except TypeError as e:
            message = str(e)
            if not any(s in message for s in _INCOMPATIBLE):
                args = kwargs = None
                raise
            line = _explain(where, message, args[1:] if bound else args, kwargs, bound)
            args = kwargs = None
            raise TypeError(line or message.splitlines()[0]) from None
        except BaseException:
            args = kwargs = None
            raise
    return call


def install(module, classes, functions, prefix=""):
    """Wraps `functions` (names in `module`) and every public method, static method and __init__ of `classes`."""
    for name in functions:
        setattr(module, name, _wrap(getattr(module, name), prefix + name, bound=False))
    for cls in classes:
        shown = prefix + cls.__name__
        for name, attr in list(vars(cls).items()):
            if name.startswith("_") and name != "__init__":
                continue
            if isinstance(attr, staticmethod):
                setattr(cls, name, staticmethod(_wrap(attr.__func__, f"{shown}.{name}", bound=False)))
            elif type(attr).__name__ == "instancemethod":
                where = shown if name == "__init__" else f"{shown}.{name}"
                setattr(cls, name, _wrap(attr, where, bound=True))
