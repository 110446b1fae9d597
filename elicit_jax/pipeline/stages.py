"""The real stage functions: thin adapters from a :class:`StageContext` to the library.

Each adapter reads its inputs, builds the library's frozen config from the stage config and
calls ONE library function (``train_policy``, ``score_file``, ``fit_thresholds``,
``filter_demos``, the simulator's collection and evaluation, the map renderer). Stages whose
library writes sibling files (scores + per-episode summary, filtered demos + drop log) get a
directory output, written atomically as a whole. :func:`resolve_config` turns a stage's raw
overrides into the library's full config, so a changed library default changes the recorded
config and re-runs the stage.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.artifact import atomic_path, dumps, make_header, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.curation_stages import (
    cupid_stage,
    quality_stage,
    resolve_cupid,
    resolve_quality,
)
from elicit_jax.pipeline.runner import StageContext, StageFn

FILTER_METHODS = {
    "filtered": ("m", "pair"),
    "filtered-valley": ("m", "pair"),
    "filtered-episode": ("m", "episode"),
    "random": ("random", None),
    "longest": ("longest", None),
    "shortest": ("shortest", None),
    "likelihood": ("likelihood", None),
    "novelty": ("novelty", None),
}
DEMOS_FILE = "demos.parquet"
SCORES_FILE = "scores.parquet"


def demos_file(path: Path) -> Path:
    """The demonstrations file of a stage output: the file itself or ``DIR/demos.parquet``."""
    return path / DEMOS_FILE if path.is_dir() else path


def _fields(cls: type, overrides: Mapping[str, Any], stage: str) -> dict[str, Any]:
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ElicitError(
            f"[{stage}] unknown option(s) {', '.join(unknown)} "
            f"(allowed: {', '.join(sorted(names))})"
        )
    return dict(overrides)


def _split(raw: Mapping[str, Any], meta: tuple[str, ...]) -> tuple[dict, dict]:
    return {k: raw[k] for k in meta if k in raw}, {k: v for k, v in raw.items() if k not in meta}


def _resolve_collect(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.sim.collect import CollectConfig
    from elicit_jax.sim.operators import operator_names

    meta, over = _split(raw, ("role",))
    known = operator_names(over["task"])
    if over["operator"] not in known:
        raise ElicitError(
            f"task '{over['task']}' has no operator '{over['operator']}' "
            f"(known: {', '.join(known)})"
        )
    cfg = CollectConfig(**_fields(CollectConfig, over, "collect"))
    return {**meta, "collect": dataclasses.asdict(cfg)}


def _resolve_train(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.policy.config import TrainConfig

    meta, over = _split(raw, ("task", "profile", "method", "operator", "study", "point"))
    cfg = TrainConfig.from_profile(meta["profile"], **_fields(TrainConfig, over, "train"))
    return {**meta, "train": cfg.to_dict()}


def _resolve_score(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.compat.measures import ScoreConfig, config_dict

    meta, over = _split(raw, ("task", "model", "policy_seed", "set", "checkpoint"))
    meta.setdefault("checkpoint", "best")
    return {**meta, "score": config_dict(ScoreConfig(**_fields(ScoreConfig, over, "score")))}


def _resolve_fit(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.compat.thresholds import FitConfig

    keys = (
        "task",
        "model",
        "compatible_operator",
        "incompatible_operator",
        "holdout_seed",
        "incompatible_seed",
        "lambda",
        "eta",
        "force",
    )
    meta, over = _split(raw, keys)
    if ("lambda" in meta) != ("eta" in meta):
        raise ElicitError("[thresholds] give both lambda and eta (manual), or neither (fit)")
    if meta["compatible_operator"] == meta["incompatible_operator"]:
        raise ElicitError("incompatible_operator must differ from the base operator")
    fit = FitConfig(**_fields(FitConfig, over, "thresholds"))
    return {**meta, "fit": dataclasses.asdict(fit)}


def _resolve_filter(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.compat.filtering import FilterConfig

    meta, over = _split(raw, ("task", "model", "method", "operator"))
    method, level = FILTER_METHODS[meta["method"]]
    over = {**over, "method": method, **({"level": level} if level else {})}
    cfg = FilterConfig(**_fields(FilterConfig, over, "filter"))
    if cfg.lambda_ is not None:
        raise ElicitError("[filter] takes its thresholds from the fit stage; set [thresholds]")
    return {**meta, "filter": dataclasses.asdict(cfg)}


def _resolve_evaluate(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.pipeline.evidence import selection_meta
    from elicit_jax.sim.evaluate import EvalConfig

    keys = ("model", "profile", "method", "operator", "seeds", "study", "point")
    meta, over = _split(raw, (*keys, "selection", "select_seed"))
    over = {"checkpoints": ["all"], "select": "best", **over}
    over["checkpoints"] = tuple(str(c) for c in over["checkpoints"])
    cfg = EvalConfig(**_fields(EvalConfig, over, "evaluate"))
    return {**meta, **selection_meta(meta, cfg.seed), "evaluate": dataclasses.asdict(cfg)}


def _resolve_deminf(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.curation.deminf import DemInfConfig

    meta, over = _split(raw, ("task", "operator"))
    return {
        **meta,
        "deminf": dataclasses.asdict(DemInfConfig(**_fields(DemInfConfig, over, "deminf"))),
    }


def _resolve_demo_score(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.curation.demo_score import DemoScoreConfig

    meta, over = _split(raw, ("model", "operator"))
    cfg = DemoScoreConfig(**_fields(DemoScoreConfig, over, "demo_score"))
    return {**meta, "task": cfg.task, "demo_score": dataclasses.asdict(cfg)}


def _resolve_curate(raw: dict[str, Any]) -> dict[str, Any]:
    """Level and accept fraction of the M-filter budget (from [filter]) and DemInf's own cut
    (from [deminf]); ``rate`` is ``m`` for the ``*-matched`` methods."""
    from elicit_jax.compat.filtering import FilterConfig
    from elicit_jax.curation.deminf import DemInfConfig

    meta, _ = _split(raw, ("task", "model", "method", "operator"))
    filt = FilterConfig(**_fields(FilterConfig, raw.get("filter", {}), "filter"))
    deminf = DemInfConfig(**_fields(DemInfConfig, raw.get("deminf", {}), "deminf"))
    return {
        **meta,
        "rate": "m" if meta["method"].endswith("-matched") else "own",
        "level": filt.level,
        "accept_fraction": filt.accept_fraction,
        "drop_fraction": deminf.drop_fraction,
    }


_RESOLVERS = {
    "collect": _resolve_collect,
    "train": _resolve_train,
    "score": _resolve_score,
    "fit-thresholds": _resolve_fit,
    "filter": _resolve_filter,
    "evaluate": _resolve_evaluate,
    "deminf": _resolve_deminf,
    "demo-score": _resolve_demo_score,
    "curate": _resolve_curate,
    "cupid": resolve_cupid,
    "quality": resolve_quality,
}


def resolve_config(kind: str, raw: dict[str, Any]) -> dict[str, Any]:
    """Full, validated config of a stage: pipeline keys plus the library config's fields
    (``map`` and ``report`` stages keep their raw config)."""
    resolver = _RESOLVERS.get(kind)
    return raw if resolver is None else resolver(raw)


def train_stage(ctx: StageContext) -> None:
    """Train on the concatenation of the ``demos*`` inputs (D_base first); a filter output
    that kept nothing contributes nothing.

    Training is deterministic, so a run of the same config on the same training arrays
    (e.g. a filter that kept nothing, leaving D_base alone, next to the base policy) is
    copied from the run that already trained them instead of training again
    (:func:`reuse_training`).
    """
    from elicit_jax.data.demos import concat_demos, read_demos
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.train import train_policy

    names = sorted(n for n in ctx.inputs if n.startswith("demos"))
    files = {n: demos_file(ctx.inputs[n]) for n in names}
    files = {n: f for n, f in files.items() if f.exists() or n == "demos0"}
    demos = concat_demos([read_demos(f) for f in files.values()])
    config = TrainConfig.from_dict(ctx.config["train"])
    if reuse_training(ctx, demos, config, files):
        return
    train_policy(demos, config, ctx.output, inputs=files, overwrite=True)
    _record_training(ctx, demos, config)


def _training_key(demos: Any, config: Any) -> str:
    import hashlib

    from elicit_jax.artifact import dumps
    from elicit_jax.policy.dataset import demos_sha256

    text = dumps(config.to_dict()) + demos_sha256(demos)
    return hashlib.sha256(text.encode()).hexdigest()


def _index_path(ctx: StageContext, key: str) -> Path:
    from elicit_jax.pipeline.runner import STATE_DIR

    return ctx.run_dir / STATE_DIR / "trainings" / f"{key}.json"


def _record_training(ctx: StageContext, demos: Any, config: Any) -> None:
    write_json(
        _index_path(ctx, _training_key(demos, config)),
        {"output": ctx.stage.output, "stage": ctx.stage.id},
    )


def reuse_training(ctx: StageContext, demos: Any, config: Any, files: Mapping[str, Path]) -> bool:
    """Copy the run of an earlier stage that trained ``config`` on the same arrays (same
    content hash) to this stage's output; False when there is none. The copy's headers name
    this stage's inputs and say where it was reused from (``reused_from``)."""
    import shutil

    from elicit_jax.artifact import content_sha256, read_json
    from elicit_jax.policy.dataset import demos_sha256

    index = _index_path(ctx, _training_key(demos, config))
    if not index.exists():
        return False
    source = ctx.run_dir / read_json(index)["output"]
    try:
        header = read_json(source / "artifact.json")
    except ElicitError:
        return False
    same_config = header.get("config") == json.loads(dumps(config.to_dict()))
    if not same_config or header.get("data_sha256") != demos_sha256(demos):
        return False
    inputs = {n: {"path": str(p), "sha256": content_sha256(p)} for n, p in files.items()}
    with atomic_path(ctx.output) as tmp:
        shutil.copytree(source, tmp)
        for head in [tmp / "artifact.json", *tmp.glob("seed*/artifact.json")]:
            data = read_json(head)
            data.update(inputs=inputs, reused_from=str(read_json(index)["output"]))
            write_json(head, data)
    ctx.console.print(f"reused the identical training run {source.name} (same config and data)")
    return True


def score_stage(ctx: StageContext) -> None:
    """Score the ``demos*`` inputs (concatenated) with the base policy of ``policy_seed``."""
    from elicit_jax.compat.measures import config_from_dict
    from elicit_jax.compat.score_file import score_file
    from elicit_jax.compat.show import scoring_bar
    from elicit_jax.data.demos import concat_demos, read_demos, write_demos
    from elicit_jax.policy.checkpoint import load_policy

    cfg = ctx.config
    which = cfg["checkpoint"]
    policy = load_policy(
        ctx.inputs["policy"], int(which) if str(which).isdigit() else which, seed=cfg["policy_seed"]
    )
    names = sorted(n for n in ctx.inputs if n.startswith("demos"))
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        source = ctx.inputs[names[0]]
        if len(names) > 1:
            source = tmp / DEMOS_FILE
            parts = [read_demos(ctx.inputs[n]) for n in names]
            write_demos(source, concat_demos(parts), inputs={n: ctx.inputs[n] for n in names})
        result = score_file(
            policy,
            source,
            tmp / SCORES_FILE,
            config_from_dict(cfg["score"]),
            policy_path=ctx.inputs["policy"],
            policy_info={"which": which, "seed": cfg["policy_seed"]},
            progress=scoring_bar,
            thresholds_source=(
                "provisional: the [score] settings' λ and η; the pipeline fits (λ, η) after "
                "scoring, and its filters and maps use the fitted values"
            ),
        )
        header = make_header(
            "pipeline-scores",
            1,
            config=dict(cfg),
            inputs=dict(ctx.inputs),
            files=[SCORES_FILE, result.episodes_path.name],
            n_pairs=result.n_pairs,
        )
        write_json(tmp / "artifact.json", header)


def fit_stage(ctx: StageContext) -> None:
    """Fit (λ, η) on the contrast scores (or record manual thresholds) with a fit report."""
    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.show import print_report
    from elicit_jax.compat.thresholds import FitConfig

    cfg = ctx.config
    job = FitJob(
        compatible=f"operator:{cfg['compatible_operator']}",
        incompatible=f"operator:{cfg['incompatible_operator']}",
        fit=FitConfig(**cfg["fit"]),
        lambda_=cfg.get("lambda"),
        eta=cfg.get("eta"),
        force=bool(cfg.get("force", False)),
    )
    fit_scores_file(ctx.inputs["scores"] / SCORES_FILE, ctx.output, job, show=print_report)


def filter_stage(ctx: StageContext) -> None:
    """Filter one D_new by its scores under the fitted thresholds (M-filter or a baseline).

    When the filter drops every pair (e.g. every demo of a conflicting operator rejected), the
    output holds no demonstrations file and the retraining uses D_base alone.
    """
    import numpy as np

    from elicit_jax.compat.filtering import FilterConfig, drop_mask, filter_demos
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds

    lam, eta, _ = read_thresholds(ctx.inputs["thresholds"])
    cfg = FilterConfig(**{**ctx.config["filter"], "lambda_": lam, "eta": eta})
    scores_path = ctx.inputs["scores"] / SCORES_FILE
    _, scores = read_scores(scores_path)
    drop, reason = drop_mask(scores, cfg)
    counts = {
        "pairs_in": int(drop.size),
        "pairs_dropped": int(drop.sum()),
        "episodes_in": int(np.unique(scores["episode"]).size),
        "episodes_out": 0,
    }
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        files = []
        if not drop.all():
            result = filter_demos(scores_path, ctx.inputs["demos"], tmp / DEMOS_FILE, cfg)
            counts["episodes_out"] = result.episodes_out
            files = [DEMOS_FILE, result.log_path.name]
        else:
            reason += "; every pair dropped, so the retraining uses D_base alone"
        header = make_header(
            "pipeline-filter",
            1,
            config=dict(ctx.config),
            inputs=dict(ctx.inputs),
            thresholds={"lambda": lam, "eta": eta},
            reason=reason,
            files=files,
            **counts,
        )
        write_json(tmp / "artifact.json", header)


def collect_stage(ctx: StageContext) -> None:
    """Collect scripted demonstrations of one operator (successes only) on C MuJoCo."""
    from rich.progress import Progress

    from elicit_jax.sim.collect import CollectConfig, collect

    cfg = CollectConfig(**ctx.config["collect"])
    with Progress(console=ctx.console, transient=True) as progress:
        bar = progress.add_task(f"collect {cfg.operator}", total=cfg.episodes)
        collect(cfg, ctx.output, progress=lambda kept, _: progress.update(bar, completed=kept))


def map_stage(ctx: StageContext) -> None:
    """Draw the compatibility map: held-out base demos and each D_new, one panel each."""
    import numpy as np

    from elicit_jax.compat.maps import write_png
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds

    lam, eta, _ = read_thresholds(ctx.inputs["thresholds"])
    cols = ("likelihood", "novelty", "operator", "incompatible")
    _, ref = read_scores(ctx.inputs["scores:contrast"] / SCORES_FILE, cols)
    keep = np.asarray(ref["operator"]).astype(str) == ctx.config["base_operator"]
    parts = [{k: np.asarray(v)[keep] for k, v in ref.items()}]
    parts[0]["operator"] = np.full(int(keep.sum()), f"{ctx.config['base_operator']} (held-out)")
    for op in ctx.config["operators"]:
        parts.append(read_scores(ctx.inputs[f"scores:{op}"] / SCORES_FILE, cols)[1])
    scores = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in cols}
    write_png(scores, lam, eta, ctx.output, axis=ctx.config.get("axis", "likelihood-error"))


def evaluate_stage(ctx: StageContext) -> None:
    """Roll out every seed and checkpoint of one training run on the same initial states;
    with held-out checkpoint selection, also on the selection seed's initial states (the
    Parquet's ``eval_seed`` column says which rollouts are which)."""
    import numpy as np
    import pandas as pd
    from rich.progress import Progress

    from elicit_jax.sim.evaluate import (
        EvalConfig,
        evaluate_refs,
        expand_policies,
        summarize,
        write_rollouts,
    )

    raw = dict(ctx.config["evaluate"])
    cfg = EvalConfig(**{**raw, "checkpoints": tuple(raw["checkpoints"])})
    label = Path(ctx.stage.output).stem
    refs = expand_policies([f"{label}={ctx.inputs['policy']}"], cfg.checkpoints)
    seeds = [cfg.seed]
    if ctx.config.get("selection") == "heldout":
        seeds = [int(ctx.config["select_seed"]), cfg.seed]
    frames = []
    with Progress(console=ctx.console, transient=True) as progress:
        for seed in seeds:
            bar = progress.add_task(
                f"evaluate {label} (evaluation seed {seed}, {cfg.rollouts} rollouts each)",
                total=len(refs),
            )
            frame = evaluate_refs(
                refs,
                dataclasses.replace(cfg, seed=seed),
                lambda ref, success, bar=bar: progress.advance(bar),
            )
            frames.append(frame.assign(eval_seed=np.int32(seed)))
    rollouts = pd.concat(frames, ignore_index=True)
    reported = rollouts[rollouts["eval_seed"] == cfg.seed]
    write_rollouts(ctx.output, rollouts, summarize(reported, cfg.select), cfg, refs)
    unstable = int(rollouts["unstable"].sum())
    if unstable:
        ctx.console.print(
            f"evaluate {label}: {unstable} of {len(rollouts)} rollouts diverged (the physics "
            "became unstable) and count as failures; MuJoCo's messages are in the log"
        )


def deminf_stage(ctx: StageContext) -> None:
    """DemInf scores of one D_new, estimated over D_base ∪ D_new."""
    from elicit_jax.curation.deminf import DemInfConfig, deminf_scores
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.data.demos import read_demos

    cfg = DemInfConfig(**ctx.config["deminf"])
    scores = deminf_scores(read_demos(ctx.inputs["demos1"]), read_demos(ctx.inputs["demos0"]), cfg)
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=dict(ctx.inputs))


def demo_score_stage(ctx: StageContext) -> None:
    """Demo-SCORE scores of one D_new from rollouts of its naive policy's checkpoints."""
    from elicit_jax.curation.demo_score import DemoScoreConfig, demo_score_scores
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.data.demos import read_demos

    raw = dict(ctx.config["demo_score"])
    cfg = DemoScoreConfig(**raw)
    scores = demo_score_scores(
        ctx.inputs["policy"],
        read_demos(ctx.inputs["demos"]),
        cfg,
        progress=lambda epoch, rate: ctx.console.print(
            f"  demo-score rollouts, epoch {epoch}: {100 * rate:.0f}% success"
        ),
    )
    inputs = {"policy": ctx.inputs["policy"] / "artifact.json", "demos": ctx.inputs["demos"]}
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=inputs)


def curate_stage(ctx: StageContext) -> None:
    """Cut one D_new by DemInf / Demo-SCORE scores, at the method's own rule or at the
    M-filter's budget under the fitted thresholds; same output layout as ``filter``."""
    from elicit_jax.compat.thresholds import read_thresholds
    from elicit_jax.curation.episodes import OwnRule, read_episode_scores
    from elicit_jax.curation.select import curate_demos, matched_rule

    cfg = ctx.config
    lam, eta, _ = read_thresholds(ctx.inputs["thresholds"])
    scores = read_episode_scores(ctx.inputs["episode_scores"])
    if cfg["rate"] == "m":
        rule = matched_rule(
            ctx.inputs["scores"] / SCORES_FILE, cfg["level"], lam, eta, cfg["accept_fraction"]
        )
    else:
        rule = OwnRule(cfg["drop_fraction"])
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        result = curate_demos(
            scores,
            ctx.inputs["demos"],
            tmp / DEMOS_FILE,
            rule,
            config=dict(cfg),
            inputs={"episode_scores": ctx.inputs["episode_scores"]},
            allow_empty=True,
        )
        files = [] if result.out_path is None else [DEMOS_FILE, result.log_path.name]
        reason = result.reason if files else result.reason + "; the retraining uses D_base alone"
        header = make_header(
            "pipeline-filter",
            1,
            config=dict(cfg),
            inputs=dict(ctx.inputs),
            thresholds={"lambda": lam, "eta": eta},
            reason=reason,
            files=files,
            trusted=scores.trusted,
            pairs_in=result.pairs_in,
            pairs_dropped=result.pairs_dropped,
            episodes_in=result.episodes_in,
            episodes_out=result.episodes_out,
        )
        write_json(tmp / "artifact.json", header)


def lambda_point_stage(ctx: StageContext) -> None:
    """Thresholds with λ at point k of ``points`` evenly spaced over the fit's margin range
    (η as fitted), for the sensitivity study."""
    from elicit_jax.compat.thresholds import THRESHOLDS_KIND, read_thresholds

    lam, eta, fit = read_thresholds(ctx.inputs["thresholds"])
    lo, hi = fit.get("report", {}).get("lambda_range", (None, None))
    if fit.get("method", "fit") != "fit" or lo is None:
        raise ElicitError(
            "the λ-sensitivity study needs fitted thresholds with a margin, not manual ones",
            ctx.inputs["thresholds"],
        )
    k, n = int(ctx.config["point"]), int(ctx.config["points"])
    point = float(lo + (hi - lo) * k / (n - 1))
    header = make_header(
        THRESHOLDS_KIND,
        1,
        config=dict(ctx.config),
        inputs={"fit": ctx.inputs["thresholds"]},
        method="sensitivity-point",
        report={"point": k, "points": n, "lambda_range": [lo, hi], "fitted_lambda": lam},
        **{"lambda": point, "eta": eta},
    )
    write_json(ctx.output, header)


def lambda_valley_stage(ctx: StageContext) -> None:
    """Thresholds with λ moved, inside the fit's margin, to the sparsest point of the familiar
    pairs of every D_new (:mod:`elicit_jax.compat.valley`); η as fitted."""
    import numpy as np

    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import THRESHOLDS_KIND, read_thresholds
    from elicit_jax.compat.valley import valley_lambda

    lam, eta, fit = read_thresholds(ctx.inputs["thresholds"])
    lo, hi = fit.get("report", {}).get("lambda_range", (None, None))
    if fit.get("method", "fit") != "fit" or lo is None:
        raise ElicitError(
            "the valley rule moves a fitted λ inside its margin; these thresholds were not fitted",
            ctx.inputs["thresholds"],
        )
    cols = ("likelihood", "novelty")
    parts = [
        read_scores(p / SCORES_FILE, cols)[1] for n, p in ctx.inputs.items() if n != "thresholds"
    ]
    ell = np.concatenate([p["likelihood"] for p in parts])
    nu = np.concatenate([p["novelty"] for p in parts])
    new_lam, report = valley_lambda(ell, nu, eta, lo, hi, lam)
    header = make_header(
        THRESHOLDS_KIND,
        1,
        config=dict(ctx.config),
        inputs=dict(ctx.inputs),
        method="new-data-valley",
        report=report,
        **{"lambda": new_lam, "eta": eta},
    )
    write_json(ctx.output, header)


def report_stage(ctx: StageContext) -> None:
    """Gather the run's artifacts and write the Markdown + HTML report."""
    from elicit_jax.pipeline.evidence import round_trip
    from elicit_jax.pipeline.gather import gather_with_rollouts
    from elicit_jax.pipeline.report import write_report

    data, rollouts = gather_with_rollouts(ctx.run_dir)
    write_report(round_trip(data), ctx.output, rollouts)


def real_registry() -> dict[str, StageFn]:
    """Stage kind -> function, for every stage whose library is wired."""
    return {
        "collect": collect_stage,
        "map": map_stage,
        "evaluate": evaluate_stage,
        "train": train_stage,
        "score": score_stage,
        "fit-thresholds": fit_stage,
        "filter": filter_stage,
        "deminf": deminf_stage,
        "demo-score": demo_score_stage,
        "cupid": cupid_stage,
        "quality": quality_stage,
        "curate": curate_stage,
        "lambda-point": lambda_point_stage,
        "lambda-valley": lambda_valley_stage,
        "report": report_stage,
    }
