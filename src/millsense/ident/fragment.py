"""TOML fragments of machine configuration written by the identification tools.

A fragment is a nested mapping with the keys of the configuration models
(:mod:`millsense.core.config`; field units in the key names) — e.g. ``axes.x.friction``,
``axes.x.disturbance_modes``, ``axes.x.ball_screw`` — that a user merges into a machine file.
:func:`to_toml` writes the small TOML subset needed (tables, strings, numbers, booleans and
flat lists of them); :func:`merge` nests results of several tools.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from millsense.core.errors import InputDataError


def _key(k: str) -> str:
    if k and all(c.isalnum() or c in "_-" for c in k):
        return k
    return '"' + k.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _value(v: object, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise InputDataError(f"fragment key {where}: value {v} is not finite")
        return repr(float(f"{v:.7g}"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x, where) for x in v) + "]"
    if hasattr(v, "item"):  # numpy scalar
        return _value(v.item(), where)
    raise InputDataError(f"fragment key {where}: cannot write a {type(v).__name__}")


def to_toml(fragment: Mapping[str, object], comments: list[str] | None = None) -> str:
    """TOML text of a nested mapping (tables for mappings, arrays of tables ``[[…]]`` for lists
    of mappings, ``key = value`` for the rest).

    Parameters
    ----------
    fragment : nested mapping of str keys.
    comments : lines written as ``# …`` at the top (provenance, the numbers of the fit).
    """
    lines = [f"# {c}" for c in (comments or [])]

    def is_array_of_tables(v: object) -> bool:
        return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, Mapping) for x in v)

    def emit(table: Mapping[str, object], path: list[str], array: bool = False) -> None:
        scalars = [
            (k, v)
            for k, v in table.items()
            if not isinstance(v, Mapping) and not is_array_of_tables(v)
        ]
        subs = [(k, v) for k, v in table.items() if isinstance(v, Mapping)]
        arrays = [(k, v) for k, v in table.items() if is_array_of_tables(v)]
        if path and (scalars or array or not (subs or arrays)):
            lines.append("")
            name = ".".join(_key(p) for p in path)
            lines.append(f"[[{name}]]" if array else f"[{name}]")
        for k, v in scalars:
            lines.append(f"{_key(k)} = {_value(v, '.'.join([*path, k]))}")
        for k, v in subs:
            assert isinstance(v, Mapping)
            emit(v, [*path, k])
        for k, v in arrays:
            assert isinstance(v, (list, tuple))
            for item in v:
                emit(item, [*path, k], array=True)

    emit(fragment, [])
    return "\n".join(lines).lstrip("\n") + "\n"


def merge(*fragments: Mapping[str, object]) -> dict[str, object]:
    """Deep merge (later fragments win on scalar keys)."""
    out: dict[str, object] = {}
    for frag in fragments:
        for k, v in frag.items():
            if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
                out[k] = merge(out[k], v)  # type: ignore[arg-type]
            elif isinstance(v, Mapping):
                out[k] = merge(v)
            else:
                out[k] = v
    return out


def kept_keys(base: Mapping[str, object], fragment: Mapping[str, object]) -> list[str]:
    """What :func:`merge` keeps of ``base`` in the leaf tables ``fragment`` rewrites.

    A leaf table (no sub-tables in the base or the fragment, e.g. ``axes.x.friction``) that the
    fragment gives only in part keeps the base's other keys: identified Coulomb friction next
    to the base's LuGre stiffness, say. One line per such table, ``"axes.x.friction: a, b"``.
    """
    out: list[str] = []

    def walk(b: Mapping[str, object], f: Mapping[str, object], path: list[str]) -> None:
        for k, fv in f.items():
            bv = b.get(k)
            if not (isinstance(fv, Mapping) and isinstance(bv, Mapping)):
                continue
            leaf = not any(isinstance(v, Mapping) for v in (*fv.values(), *bv.values()))
            if leaf:
                kept = [key for key in bv if key not in fv and key != "source"]
                if kept:
                    out.append(f"{'.'.join([*path, k])}: {', '.join(kept)}")
            else:
                walk(bv, fv, [*path, k])

    walk(base, fragment, [])
    return out


def write_fragment(
    path: str | Path, fragment: Mapping[str, object], comments: list[str] | None = None
) -> None:
    """Write :func:`to_toml` of ``fragment`` to ``path`` (atomically, decision 0921)."""
    from millsense.io.safe_output import write_text

    write_text(path, to_toml(fragment, comments))
