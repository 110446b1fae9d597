"""``elicit-jax export``: hand demonstrations back to robomimic, LeRobot or ``.npz``.

What is written depends on what is asked and where the demonstrations came from:

============  ==============================  =================================================
format        asked                           writes
============  ==============================  =================================================
robomimic     ``--mask-key K``                a copy of the source file with ``mask/K`` listing
                                              the selected demos (``--in-place``: the mask goes
                                              into the source file itself)
robomimic     no mask key                     a new file holding the demos' own arrays
lerobot       ``-o DIR``, whole episodes of   those episodes of the source, every feature kept
              one LeRobot dataset             (cameras, videos)
lerobot       ``-o DIR`` otherwise, or        a new dataset holding the demos' own arrays
              ``--fresh``
lerobot       ``-o list.json``                an episode list for ``LeRobotDataset(episodes=)``
npz           —                               the demos as an ``.npz`` archive
============  ==============================  =================================================

A selection of the source (mask, LeRobot subset, episode list) must consist of whole source
episodes, each still in the source as imported: each one's length and content hash (recorded
at import) are checked, not the file's bytes, so masks added by other tools (robomimic's
``split_train_val.py``) or by an earlier export do not get in the way. Demos with dropped
pairs (``filter --level pair``) or from several datasets cannot be a selection: they are
written as a new file instead.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from elicit_jax.artifact import check_outputs, make_header, read_header
from elicit_jax.data.demos import Demos, read_demos
from elicit_jax.data.export_config import (
    EXPORT_KIND,
    EXPORT_SCHEMA_VERSION,
    ExportConfig,
    is_lerobot_dataset,
)
from elicit_jax.data.lerobot_record import carried_record, lerobot_indices
from elicit_jax.data.selection import (
    Selection,
    provenance_leaves,
    read_selection,
    recorded_env_args,
    single_source,
    write_episode_list,
)
from elicit_jax.data.source_check import check_selection
from elicit_jax.errors import ElicitError

LOAD_LIST = (
    'LeRobotDataset(REPO_ID, root=ROOT, episodes=json.load(open("{path}"))["source_episodes"])'
)


def _check_out(cfg: ExportConfig) -> None:
    out = Path(cfg.out or "")
    if out.resolve() == Path(cfg.selection).resolve():
        raise ElicitError("output would overwrite the selection it is made from", out)
    check_outputs(
        [out], [cfg.selection, cfg.source], overwrite=cfg.overwrite, replaceable=is_lerobot_dataset
    )


def _selected_demos(cfg: ExportConfig, sel: Selection) -> Demos:
    if read_header(cfg.selection).get("kind") != "demos":
        raise ElicitError(
            "writing a new file needs a demos .parquet (its arrays), not an episode list",
            cfg.selection,
        )
    return read_demos(cfg.selection, bounds="warn").select_episodes(sel.episodes)


def _source(
    cfg: ExportConfig, sel: Selection, importer: str, instead: str
) -> tuple[dict, str, Selection]:
    """The selection's source dataset (its provenance and path) for an ``importer`` export,
    and the selection with names in that dataset: demos imported from a LeRobot folder that
    elicit-jax wrote from robomimic demos name their ``origin`` file's demos."""
    try:
        prov = single_source(sel.provenance, cfg.selection)
    except ElicitError as e:
        raise ElicitError(f"{e}; {instead}") from e
    origin = prov.get("origin") or {}
    if prov.get("importer") != importer and origin.get("importer") == importer:
        by_index = {str(i): n for n, i in (prov.get("episode_index") or {}).items()}
        names = tuple(by_index.get(n, n) for n in sel.source_episodes)  # episode lists
        sel, prov = dataclasses.replace(sel, source_episodes=names), dict(origin)
    if prov.get("importer") != importer:
        raise ElicitError(
            f"the demonstrations were imported from {prov.get('importer')} data "
            f"({prov.get('source')}), not {importer}; {instead}",
            cfg.selection,
        )
    return prov, str(cfg.source or prov["source"]), sel


def mask_source(selection: str, instead: str) -> str:
    """The robomimic file a mask of ``selection`` marks; ``instead`` ends the error if none."""
    cfg = ExportConfig(selection=selection, format="robomimic", out=selection)
    return _source(cfg, read_selection(selection), "robomimic", instead)[1]


def _fps(cfg: ExportConfig, demos: Demos) -> tuple[int, str]:
    """Frame rate of a new LeRobot dataset and where it came from."""
    if cfg.fps is not None:
        rate, why = cfg.fps, "--fps"
    else:
        rate, why = None, ""
        for p in provenance_leaves(demos.provenance):
            tc, env = p.get("task_config") or {}, (p.get("env_args") or {}).get("env_kwargs") or {}
            if p.get("fps"):
                rate, why = p["fps"], f"the source dataset {p.get('source')}"
            elif tc.get("substeps") and tc.get("timestep"):
                rate, why = 1.0 / (tc["substeps"] * tc["timestep"]), "the task's control period"
            elif env.get("control_freq"):
                rate, why = env["control_freq"], "robomimic env_args control_freq"
            if rate:
                break
        if rate is None:
            raise ElicitError(
                "cannot tell the demonstrations' frame rate (LeRobot records one); pass --fps",
                cfg.selection,
            )
    if abs(rate - round(rate)) > 1e-6:
        raise ElicitError(f"LeRobot needs an integer frame rate, got {rate:g} from {why}")
    return round(rate), why


def export_dataset(
    cfg: ExportConfig, progress: Any = None, instead: str | None = None
) -> dict[str, Any]:
    """Export the selected episodes; returns a summary (what was written where, and notes).

    Args:
      cfg: what to export and how.
      progress: optional callable ``progress(bytes)``, advanced while an in-place mask
        export hashes the file.
      instead: what the caller's user can do when the selection cannot be a mask or an
        episode list of its source (None: the command line's advice, e.g. drop --mask-key).
    """
    sel = read_selection(cfg.selection, cfg.episodes)
    if not cfg.in_place:
        _check_out(cfg)
    sel, duplicates = _without_duplicates(cfg, sel)
    config = dataclasses.asdict(cfg)
    header = make_header(
        EXPORT_KIND, EXPORT_SCHEMA_VERSION, config=config, inputs={"selection": cfg.selection}
    )
    summary: dict[str, Any] = {"format": cfg.format, "out": cfg.out, "episodes": len(sel.episodes)}
    if cfg.format == "robomimic" and cfg.mask_key:
        summary.update(_mask(cfg, sel, header, progress, instead))
    elif cfg.format == "robomimic":
        summary.update(_fresh_robomimic(cfg, sel, header))
    elif cfg.format == "lerobot" and Path(cfg.out or "").suffix == ".json":
        summary.update(_episode_list(cfg, sel, instead))
    elif cfg.format == "lerobot":
        summary.update(_lerobot(cfg, sel, header))
    else:
        from elicit_jax.data.npz import export_npz

        demos = _selected_demos(cfg, sel)
        export_npz(demos, str(cfg.out), header=header)
        summary.update(steps=demos.n_steps)
    if duplicates:
        summary["notes"] = [duplicates, *summary.get("notes", [])]
    return summary


def _without_duplicates(cfg: ExportConfig, sel: Selection) -> tuple[Selection, str]:
    """The selection without episodes identical to an earlier selected one (an export never
    carries a demonstration twice), and a note saying which were left out ("" if none)."""
    from elicit_jax.data.duplicates import find_duplicates

    if read_header(cfg.selection).get("kind") != "demos":
        return sel, ""
    demos = read_demos(cfg.selection, bounds="warn").select_episodes(sel.episodes)
    dups = find_duplicates([demos])
    if not dups:
        return sel, ""
    gone = {d.episode for d in dups}
    keep = [i for i, e in enumerate(sel.episodes) if e not in gone]

    def pick(values: Any) -> Any:
        return None if values is None else tuple(values[i] for i in keep)

    sel = dataclasses.replace(
        sel,
        episodes=pick(sel.episodes),
        source_episodes=pick(sel.source_episodes),
        operators=pick(sel.operators),
        lengths=pick(sel.lengths),
    )
    pairs = ", ".join(f"{d.episode} (= {d.of_episode})" for d in dups[:5])
    more = f" and {len(dups) - 5} more" if len(dups) > 5 else ""
    return sel, (
        f"left out {len(dups)} episode(s) identical to an earlier selected one: {pairs}{more}"
    )


def _mask(
    cfg: ExportConfig, sel: Selection, header: dict, progress: Any, advice: str | None
) -> dict[str, Any]:
    from elicit_jax.data.robomimic_export import add_mask

    instead = advice or "drop --mask-key to write them as a new robomimic file"
    prov, source, sel = _source(cfg, sel, "robomimic", instead)
    check_selection(sel, prov, source, "robomimic", advice or instead + " with only the kept steps")
    names = add_mask(
        source,
        None if cfg.in_place else cfg.out,
        cfg.mask_key or "",
        sel.source_episodes,
        overwrite=cfg.overwrite,
        header=header,
        progress=progress,
    )
    return {
        "mode": "mask",
        "out": source if cfg.in_place else cfg.out,
        "source": source,
        "mask_key": cfg.mask_key,
        "demos": names,
        "in_place": cfg.in_place,
    }


def _fresh_robomimic(cfg: ExportConfig, sel: Selection, header: dict) -> dict[str, Any]:
    from elicit_jax.data.robomimic_export import write_fresh

    demos = _selected_demos(cfg, sel)
    try:
        prov = single_source(demos.provenance, cfg.selection)
    except ElicitError:
        prov = {}
    env = recorded_env_args(prov or demos.provenance)
    written = write_fresh(
        demos,
        str(cfg.out),
        env_args=env,
        valid_fraction=cfg.valid_fraction,
        seed=cfg.seed,
        header=header,
    )
    ops = [k for k in written["masks"] if k not in ("train", "valid")]
    unit = all(float(x) >= -1 for x in _flat(demos.action_low)) and all(
        float(x) <= 1 for x in _flat(demos.action_high)
    )
    reimport = (
        f"elicit-jax import {cfg.out} --obs-keys {','.join(written['obs_keys'])} "
        f"--operators-from-masks {','.join(ops)}"
        + ("" if unit else " --action-bounds data")
        + " -o demos.parquet"
    )
    written["notes"] += _imported_note(demos, "robomimic")
    return {"mode": "new file", **written, "reimport": reimport}


def _imported_note(demos: Demos, fmt: str) -> list[str]:
    """Say that a new file holds only what was imported, when the demos came from a dataset."""
    leaves = [p for p in provenance_leaves(demos.provenance) if p.get("importer")]
    if not leaves:
        return []
    keys = sorted({k for p in leaves for k in p.get("obs_keys") or []})
    keep = {
        "robomimic": "a --mask-key export marks the demos in the whole source file instead",
        "lerobot": "a selection of the source (without --fresh) keeps every feature",
    }
    ways = keep[fmt] if fmt in {str(p["importer"]) for p in leaves} else ""
    return [
        f"only what was imported is written (observation {', '.join(keys) or 'obs'}, actions, "
        f"rewards): other keys of the source (cameras, states) are not"
        + (f"; {ways}" if ways else "")
    ]


def _flat(bound: Any) -> list[float]:
    return list(bound) if isinstance(bound, tuple | list) else [bound]


def _episode_list(cfg: ExportConfig, sel: Selection, advice: str | None) -> dict[str, Any]:
    instead = "an episode list names episodes of a LeRobot dataset; write a folder instead"
    prov, source, sel = _source(cfg, sel, "lerobot", advice or instead)
    check_selection(sel, prov, source, "lerobot", advice or "write a folder with --fresh instead")
    indices = lerobot_indices(sel.source_episodes, prov, source)
    sel = dataclasses.replace(sel, source_episodes=tuple(str(i) for i in indices))
    write_episode_list(
        str(cfg.out), sel, config=dataclasses.asdict(cfg), inputs={"selection": cfg.selection}
    )
    return {
        "mode": "episode list",
        "source": source,
        "source_episodes": indices,
        "load": LOAD_LIST.format(path=cfg.out),
    }


def _lerobot(cfg: ExportConfig, sel: Selection, header: dict) -> dict[str, Any]:
    from elicit_jax.data.lerobot_fresh import write_fresh

    subset = not cfg.fresh
    if subset:
        try:
            prov = single_source(sel.provenance, cfg.selection)
        except ElicitError:
            prov = {}
        subset = prov.get("importer") == "lerobot"
    if not subset:
        demos = _selected_demos(cfg, sel)
        fps, why = _fps(cfg, demos)
        written = write_fresh(
            demos, str(cfg.out), fps=fps, version=cfg.version or "v3.0", header=header
        )
        written["notes"].insert(0, f"frame rate {fps} fps (from {why})")
        written["notes"] += _imported_note(demos, "lerobot")
        return {"mode": "new dataset", "fps": fps, **written}
    from elicit_jax.data.lerobot_export import export_lerobot

    source = str(cfg.source or prov["source"])
    lengths = check_selection(
        sel, prov, source, "lerobot", "pass --fresh to write the kept steps as a new dataset"
    )
    indices = lerobot_indices(sel.source_episodes, prov, source)
    chosen = sorted(zip(indices, sel.source_episodes, lengths, sel.operators, strict=True))
    hashes = prov.get("episode_sha256") or {}
    header["episodes"] = [
        {
            "episode_index": i,
            "length": n,
            **({"sha256": hashes[name]} if name in hashes else {}),
            "operator": op,
            "source_episode": name,
        }
        for i, (_, name, n, op) in enumerate(chosen)
    ]
    if hashes:  # the frames are copied as they are: the import's hashes hold for them
        header["sha256_of"] = {"obs": list(prov.get("obs_keys") or ["observation.state"])}
    # what the source's own record says of its features, and where the names come from
    header.update(carried_record(Path(source)))
    if "origin" in prov:
        header["origin"] = prov["origin"]
    else:  # the names are the source folder's own episode indices
        header.pop("origin", None)
    written = export_lerobot(source, str(cfg.out), indices, version=cfg.version, header=header)
    return {"mode": "selection of the source", "source": source, **written}
