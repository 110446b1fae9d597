"""Whether a selection still names whole, unchanged episodes of its source dataset.

An export that marks or picks episodes *in the source* (a robomimic mask, a LeRobot subset or
episode list) checks each selected episode against the source as it is now: its length, and
its content hash against the one recorded at import. Other tools' changes to the file (masks
added by robomimic's scripts, an earlier export) do not get in the way.
"""

from __future__ import annotations

from typing import Any

from elicit_jax.artifact import file_sha256
from elicit_jax.data.selection import Selection
from elicit_jax.errors import ElicitError


def check_selection(
    sel: Selection, prov: dict[str, Any], source: str, importer: str, hint: str
) -> list[int]:
    """Check that each selected episode is a whole source episode, unchanged since import.

    Args:
      sel: the selection.
      prov: its single source's provenance (obs keys, per-episode hashes).
      source: the dataset to check against.
      importer: ``robomimic`` or ``lerobot``.
      hint: what to do instead when episodes are not whole (appended to the error).

    Returns:
      The source length of each selected episode.
    """
    names = list(sel.source_episodes)
    keys = prov.get("obs_keys") or None
    if importer == "robomimic":
        from elicit_jax.data.robomimic import DEFAULT_OBS_KEYS
        from elicit_jax.data.robomimic_export import read_demo_digests

        found = read_demo_digests(source, list(dict.fromkeys(names)), keys or DEFAULT_OBS_KEYS)
    else:
        from elicit_jax.data.lerobot import import_lerobot
        from elicit_jax.data.lerobot_record import lerobot_indices

        wanted = lerobot_indices(sorted(set(names)), prov, source)
        back = import_lerobot(source, obs_keys=keys, episodes=wanted)
        digests = back.provenance["episode_sha256"]
        found = {
            str(back.extra["source_episode"][s]): (
                e - s,
                digests[str(back.extra["source_episode"][s])],
            )
            for _, s, e in back.episode_bounds()
        }
        lost = [n for n in names if n not in found]
        if lost:
            raise ElicitError(
                f"episode {lost[0]} is no longer where it was recorded (the folder changed?); "
                "pass the original dataset as --source",
                source,
            )
    recorded = prov.get("episode_sha256")
    for i, name in enumerate(names):
        length, digest = found[name]
        if names.count(name) > 1:
            raise ElicitError(
                f"source episode {name} is split over {names.count(name)} episodes of the "
                f"selection (filter --pair-mode split?), and a selection of the source lists "
                f"whole episodes; {hint}",
                source,
            )
        if sel.lengths is not None and sel.lengths[i] != length:
            raise ElicitError(
                f"episode {sel.episodes[i]} holds {sel.lengths[i]} of source episode {name}'s "
                f"{length} steps (pairs dropped by filter --level pair?), and a selection of the "
                f"source lists whole episodes; {hint}",
                source,
            )
        if recorded is not None and recorded.get(name) != digest:
            raise ElicitError(
                f"episode {name} differs from the one imported (its obs, actions or rewards "
                "changed); pass the original dataset as --source",
                source,
            )
    if recorded is None and prov.get("sha256") and file_sha256(source) != prov["sha256"]:
        raise ElicitError(
            "content differs from the dataset the demonstrations were imported from (sha256 "
            "mismatch; they were imported before per-episode hashes were recorded: re-import "
            "to check episodes, not bytes); pass the original as --source",
            source,
        )
    return [found[n][0] for n in names]
