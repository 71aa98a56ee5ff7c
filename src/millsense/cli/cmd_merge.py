"""``millsense merge``: a machine file from a base machine and ``millsense identify`` fragments.

``millsense merge BASE FRAGMENT... -o MACHINE.toml``: BASE is a preset name or a machine TOML;
each fragment's tables are deep-merged over it in order (a later key wins; an array of tables,
e.g. ``disturbance_modes_at``, is replaced whole), the result is validated as a machine and
written. A leaf table a fragment gives in part keeps the base's other keys, and a note says
which (:func:`millsense.ident.fragment.kept_keys`). The merged file configures the
estimators (``estimate --machine``) and, for ``simulate``, the virtual machine as well.
"""

from __future__ import annotations

from pathlib import Path

import typer

from millsense.cli.main import app


@app.command()
def merge(
    base: str = typer.Argument(..., help="Machine preset or .toml the fragments go into."),
    fragments: list[Path] = typer.Argument(..., help="Fragments from millsense identify."),
    out: Path = typer.Option(..., "-o", "--output", help="Machine TOML written."),
) -> None:
    """Merge identify fragments into a machine file (validated before it is written)."""
    from millsense.core.config import MachineConfig, parse_config, read_toml
    from millsense.core.presets import preset_data
    from millsense.ident.fragment import kept_keys, write_fragment
    from millsense.ident.fragment import merge as deep_merge
    from millsense.io.safe_output import check_outputs

    inputs: list[tuple[str, Path | str | None]] = [("one of the fragments", f) for f in fragments]
    inputs.append(("the base machine file", base))
    check_outputs(inputs, {"-o": out})
    data, source = preset_data(MachineConfig, base)
    merged = data
    notes: list[str] = []
    for f in fragments:
        frag = read_toml(f)
        notes += [f"{f.name}: keeps from the base {k}" for k in kept_keys(merged, frag)]
        merged = deep_merge(merged, frag)
        # validate after each fragment so that the message names the one that breaks it
        parse_config(MachineConfig, merged, f"{source} + {f}")
    machine = parse_config(MachineConfig, merged, source)
    head = [f"millsense merge {base} " + " ".join(str(f) for f in fragments)]
    write_fragment(out, merged, head)
    for n in notes:
        typer.echo(f"millsense: note: {n}", err=True)
    typer.echo(
        f"wrote {out}: machine {machine.name!r}, axes {', '.join(machine.axes)}, "
        f"{len(fragments)} fragment(s) merged"
    )
