"""Typed objects as plain data: a JSON tree and a few numeric arrays, read back without
running code.

What a study keeps for ``--resume`` (`fabplan.study.cache`) must not be able to run code
when it is read: a study folder may come from someone else. Pickle can; this format
cannot. An object is written as JSON whose objects name their type, and its numpy arrays
are packed by dtype into one flat array each, for an ``.npz`` file read with
``allow_pickle=False``. Reading builds only the types the caller lists, through their
constructors, from numbers, strings and arrays.

Encoded forms (everything else is plain JSON):

- ``{"$tuple": [...]}``, ``{"$dict": [[key, value], ...]}`` (keys that are not strings,
  or start with ``$``);
- ``{"$scalar": DTYPE, "value": v}`` for numpy scalars;
- ``{"$array": DTYPE, "shape": [...], "at": OFFSET}``: the values at ``OFFSET`` of the
  packed array of that dtype;
- ``{"$type": NAME, "fields": {...}}`` for a dataclass (its init fields), and
  ``{"$type": NAME, "state": ...}`` for a class with ``to_data()`` and
  ``from_data(state)``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["encode", "decode", "packed_bytes", "ARRAY_KINDS"]

#: dtype kinds an array may have: booleans, integers, floats, complex numbers, text
ARRAY_KINDS = "biufcU"


class _Writer:
    def __init__(self, types: Mapping[str, type]) -> None:
        self.names = {cls: name for name, cls in types.items()}
        self.chunks: dict[str, list[np.ndarray]] = {}
        self.sizes: dict[str, int] = {}

    def array(self, value: np.ndarray) -> dict:
        if value.dtype.kind not in ARRAY_KINDS:
            raise TypeError(f"an array of dtype {value.dtype} cannot be stored")
        dtype = value.dtype.str
        at = self.sizes.get(dtype, 0)
        self.chunks.setdefault(dtype, []).append(np.ravel(value))
        self.sizes[dtype] = at + value.size
        return {"$array": dtype, "shape": list(value.shape), "at": at}

    def tree(self, obj: Any) -> Any:
        if obj is None or isinstance(obj, (bool, str)) or type(obj) in (int, float):
            return obj
        if isinstance(obj, np.ndarray):
            return self.array(obj)
        if isinstance(obj, np.generic):
            if obj.dtype.kind not in "biuf":
                raise TypeError(f"a numpy scalar of dtype {obj.dtype} cannot be stored")
            return {"$scalar": obj.dtype.str, "value": obj.item()}
        if type(obj) is list:
            return [self.tree(v) for v in obj]
        if type(obj) is tuple:
            return {"$tuple": [self.tree(v) for v in obj]}
        if type(obj) is dict:
            if all(type(k) is str and not k.startswith("$") for k in obj):
                return {k: self.tree(v) for k, v in obj.items()}
            return {"$dict": [[self.tree(k), self.tree(v)] for k, v in obj.items()]}
        name = self.names.get(type(obj))
        if name is None:
            raise TypeError(f"{type(obj).__qualname__} is not a type this file may hold")
        if dataclasses.is_dataclass(obj):
            return {"$type": name, "fields": {f.name: self.tree(getattr(obj, f.name))
                                              for f in dataclasses.fields(obj) if f.init}}
        return {"$type": name, "state": self.tree(obj.to_data())}

    def packed(self) -> list[np.ndarray]:
        return [np.concatenate(chunks) for chunks in self.chunks.values()]

    def dtypes(self) -> list[str]:
        return list(self.chunks)


def encode(obj: Any, types: Mapping[str, type]) -> tuple[dict, list[np.ndarray]]:
    """`obj` as a JSON tree and the arrays that go with it.

    Parameters
    ----------
    obj : nested lists, tuples, dicts, numbers, strings, numpy arrays and scalars, and
        instances of `types` (dataclasses, or classes with ``to_data``/``from_data``).
    types : name -> class: the only classes the data may hold.

    Returns
    -------
    data : the tree, for ``json.dumps`` (NaN and infinities become JSON's NaN and
        Infinity, which ``json.loads`` reads back).
    arrays : 1-D arrays, one per dtype (for ``numpy.savez``).

    Raises
    ------
    TypeError
        For a value of any other type (a function, an object array, ...).

    Examples
    --------
    >>> import json
    >>> data, arrays = encode({"x": np.arange(3), "t": (1, 2.5)}, {})
    >>> decode(json.loads(json.dumps(data)), arrays, {})
    {'x': array([0, 1, 2]), 't': (1, 2.5)}
    """
    writer = _Writer(types)
    tree = writer.tree(obj)
    return {"dtypes": writer.dtypes(), "tree": tree}, writer.packed()


def packed_bytes(data: Any) -> list[int]:
    """The bytes each packed array of `data` (as `encode` gave it) holds by its array
    references: what a reader may expect before it unpacks anything (a crafted file
    that claims more is refused unread).

    Raises
    ------
    ValueError
        For malformed data.
    """
    if not isinstance(data, dict) or not isinstance(data.get("dtypes"), list):
        raise ValueError("not a typed data file")
    dtypes = data["dtypes"]
    sizes = dict.fromkeys(map(str, dtypes), 0)
    stack = [data.get("tree")]
    while stack:
        node = stack.pop()
        if isinstance(node, list):
            stack.extend(node)
        elif isinstance(node, dict):
            if "$array" in node:
                shape = node.get("shape")
                if not (isinstance(shape, list) and all(type(n) is int and n >= 0 for n in shape)
                        and node["$array"] in sizes):
                    raise ValueError("a malformed array reference")
                sizes[node["$array"]] += math.prod(shape)
            else:
                stack.extend(node.values())
    return [sizes[str(d)] * np.dtype(str(d)).itemsize for d in dtypes]


def _conforms(value: Any, hint: Any, types: Mapping[str, type]) -> bool:
    """Whether `value` has the type `hint` (a resolved annotation) says, as far as a kept
    result needs: unknown hints pass."""
    import types as builtin_types
    import typing

    if hint is Any or hint is typing.Any:
        return True
    origin = typing.get_origin(hint)
    if origin in (typing.Union, builtin_types.UnionType):
        return any(_conforms(value, h, types) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is float:
        return isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if hint in (bool, str):
        return isinstance(value, (hint, np.bool_)) if hint is bool else isinstance(value, str)
    if hint is np.ndarray or origin is np.ndarray:
        return isinstance(value, np.ndarray)
    if origin in (list, tuple, dict):
        return isinstance(value, origin)
    if isinstance(hint, type) and hint in types.values():
        return type(value) is hint
    return True


class _Reader:
    def __init__(self, arrays: Sequence[np.ndarray], dtypes: Any, types: Mapping[str, type]):
        if not isinstance(dtypes, list) or len(dtypes) != len(arrays):
            raise ValueError("the arrays do not match the data")
        self.packed: dict[str, np.ndarray] = {}
        for k, dtype in enumerate(dtypes):
            values = np.asarray(arrays[k])
            if values.ndim != 1 or values.dtype.kind not in ARRAY_KINDS or (
                    values.size and values.dtype.str != dtype):
                raise ValueError(f"packed array {k} is not a flat array of {dtype}")
            self.packed[dtype] = values
        self.types = types
        self.hints: dict[type, dict] = {}

    def _hints(self, cls: type) -> dict:
        """The resolved field annotations of `cls` (its listed types resolved by name);
        {} when they cannot be resolved."""
        import typing

        if cls not in self.hints:
            try:
                self.hints[cls] = typing.get_type_hints(cls, localns={**self.types, "np": np})
            except Exception:             # an annotation this reader cannot resolve
                self.hints[cls] = {}
        return self.hints[cls]

    def array(self, node: dict) -> np.ndarray:
        dtype, shape, at = node["$array"], node["shape"], node["at"]
        if not (isinstance(shape, list) and all(type(n) is int and n >= 0 for n in shape)
                and type(at) is int and at >= 0 and dtype in self.packed):
            raise ValueError("a malformed array reference")
        size = math.prod(shape)
        values = self.packed[dtype]
        if at + size > values.size:
            raise ValueError("an array reference beyond the stored values")
        return values[at:at + size].reshape(shape).copy()

    def tree(self, node: Any) -> Any:
        if isinstance(node, list):
            return [self.tree(v) for v in node]
        if not isinstance(node, dict):
            return node
        if "$array" in node:
            return self.array(node)
        if "$tuple" in node:
            return tuple(self.tree(v) for v in node["$tuple"])
        if "$dict" in node:
            return {self.tree(k): self.tree(v) for k, v in node["$dict"]}
        if "$scalar" in node:
            dtype = np.dtype(node["$scalar"])
            if dtype.kind not in "biuf":
                raise ValueError(f"a scalar of dtype {dtype}")
            return dtype.type(node["value"])
        if "$type" in node:
            cls = self.types.get(node["$type"])
            if cls is None:
                raise ValueError(f"type {node['$type']!r} may not be read")
            if dataclasses.is_dataclass(cls):
                fields = node["fields"]
                if not isinstance(fields, dict):
                    raise ValueError(f"malformed fields of {node['$type']}")
                values = {k: self.tree(v) for k, v in fields.items()}
                hints = self._hints(cls)
                for key, value in values.items():
                    if key in hints and not _conforms(value, hints[key], self.types):
                        raise ValueError(f"{node['$type']}.{key} is a {type(value).__name__}, "
                                         "not what the field holds")
                return cls(**values)
            return cls.from_data(self.tree(node["state"]))    # type: ignore[attr-defined]
        if any(k.startswith("$") for k in node):
            raise ValueError(f"unknown entry {sorted(node)[0]!r}")
        return {k: self.tree(v) for k, v in node.items()}


def decode(data: Any, arrays: Sequence[np.ndarray], types: Mapping[str, type]) -> Any:
    """The object `encode` gave as `data` (read back from JSON) and `arrays`.

    Raises
    ------
    ValueError
        When the data is malformed, names a type not in `types`, or does not fit the
        arrays (a ``TypeError`` from a constructor that does not take the fields is
        raised as is).
    """
    if not isinstance(data, dict) or "tree" not in data:
        raise ValueError("not a typed data file")
    return _Reader(arrays, data.get("dtypes"), types).tree(data["tree"])
