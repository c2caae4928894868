"""Sweep results: [`SweepResult`][vcjax.sweep.results.SweepResult], statistics
([`summarize`][vcjax.sweep.results.summarize]), ``.npz`` files
([`save_results`][vcjax.sweep.results.save_results],
[`load_results`][vcjax.sweep.results.load_results]) and the merge of per-process parts."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from vcjax.metrics import FLAGS
from vcjax.sweep.spec import SweepSpec, spec_from_dict, spec_to_dict

__all__ = [
    "SweepResult",
    "run_timing",
    "summarize",
    "save_results",
    "load_results",
    "merge_results",
    "spec_to_dict",
    "spec_from_dict",
    "wave_table",
    "WAVE_TABLE_METRICS",
]


@dataclasses.dataclass
class SweepResult:
    """Per-scenario results of a sweep (host numpy arrays, aligned with ``index``).

    Attributes:
        spec: the [`SweepSpec`][vcjax.sweep.spec.SweepSpec].
        index: (n,) scenario numbers (sorted; all of them unless this is one process's share).
        scenarios: sampled parameters, e.g. ``"eta0"`` (n, n_eta), ``"current_speed"`` (n,),
            ``"model_factors"`` (n, F) (columns: the spec's model fields).
        metrics: ``metrics[variant][name]`` (n,):
            [`vcjax.metrics.metric_names`][vcjax.metrics.metric_names] and
            ``vcjax.metrics.FLAGS``.
        traces: ``traces[variant]["e"]`` (n, P) cross-track error [m], ``["xy"]`` (n, P, 2)
            position [m] at times ``trace_t`` (P,) [s] (float32).
        trace_t: (P,) [s].
        wall_s: wall time of the sweep [s]; devices: number of devices used (per process).
        timing: ``timing[variant]``: [`run_timing`][vcjax.sweep.results.run_timing] (compile and run
            seconds, throughput).
        interrupted: the sweep was stopped (SIGINT / SIGTERM) after its first ``len(index)``
            scenarios' chunks; the result is valid, only smaller.
    """

    spec: SweepSpec
    index: np.ndarray
    scenarios: dict
    metrics: dict
    traces: dict
    trace_t: np.ndarray
    wall_s: float = 0.0
    devices: int = 1
    timing: dict = dataclasses.field(default_factory=dict)
    interrupted: bool = False  # stopped by a signal: ``index`` holds the scenarios that ran

    def to_xarray(self):
        """An ``xarray.Dataset``: dimensions ``variant`` x ``scenario``, sampled inputs and
        metrics as labelled variables, units as attributes
        ([`vcjax.sweep.labelled`][vcjax.sweep.labelled];
        needs ``pip install "vcjax[xarray]"``)."""
        from vcjax.sweep.labelled import to_xarray

        return to_xarray(self)


def run_timing(compile_s: float, run_s: float, scenarios: int, steps: int, devices: int) -> dict:
    """One variant's timing: ``compile_s`` (trace + lower + XLA compile) [s], ``run_s``
    (every chunk run and fetched, compilation excluded) [s], ``traj_steps_per_s`` =
    ``scenarios x steps / run_s`` (None when nothing ran), and the counts."""
    rate = scenarios * steps / run_s if run_s > 0 and scenarios else None
    return {
        "compile_s": float(compile_s),
        "run_s": float(run_s),
        "traj_steps_per_s": rate,
        "scenarios": int(scenarios),
        "steps": int(steps),
        "devices": int(devices),
    }


def _merge_timing(parts: list[SweepResult]) -> dict:
    """Processes run in parallel: the slowest sets compile and run time; scenarios add up."""
    out = {}
    for v in parts[0].timing:
        ts = [p.timing[v] for p in parts if v in p.timing]
        out[v] = run_timing(
            max(t["compile_s"] for t in ts),
            max(t["run_s"] for t in ts),
            sum(t["scenarios"] for t in ts),
            ts[0]["steps"],
            sum(t["devices"] for t in ts),
        )
    return out


def merge_results(parts: list[SweepResult]) -> SweepResult:
    """Combine the per-process parts of one sweep (sorted by scenario index)."""
    if not parts:
        raise ValueError("parts: nothing to merge")
    spec = parts[0].spec
    if any(p.spec != spec for p in parts):
        raise ValueError("parts: results of different sweeps")
    devices = sum(p.devices for p in parts)
    timing = _merge_timing(parts)
    parts = [p for p in parts if p.index.size] or parts[:1]  # a process may have had no chunk
    index = np.concatenate([p.index for p in parts])
    order = np.argsort(index, kind="stable")
    if len(np.unique(index)) != len(index):
        raise ValueError("parts: overlapping scenario indices")

    def cat(get):
        return np.concatenate([get(p) for p in parts])[order]

    return SweepResult(
        spec=spec,
        index=index[order],
        scenarios={k: cat(lambda p, k=k: p.scenarios[k]) for k in parts[0].scenarios},
        metrics={
            v: {k: cat(lambda p, v=v, k=k: p.metrics[v][k]) for k in parts[0].metrics[v]}
            for v in parts[0].metrics
        },
        traces={
            v: {k: cat(lambda p, v=v, k=k: p.traces[v][k]) for k in parts[0].traces[v]}
            for v in parts[0].traces
        },
        trace_t=parts[0].trace_t,
        wall_s=max(p.wall_s for p in parts),
        devices=devices,
        timing=timing,
        interrupted=any(p.interrupted for p in parts),
    )


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {k: None for k in ("mean", "std", "p5", "p50", "p95", "min", "max")}
    p5, p50, p95 = np.percentile(x, [5, 50, 95])
    vals = dict(mean=x.mean(), std=x.std(), p5=p5, p50=p50, p95=p95, min=x.min(), max=x.max())
    return {k: (float(v) if np.isfinite(v) else None) for k, v in vals.items()}


#: the metrics [`wave_table`][vcjax.sweep.results.wave_table] bins
WAVE_TABLE_METRICS = ("rms_cross_track_e", "rms_depth_err")


def wave_table(result: SweepResult, hs_bins: int = 3, depth_bins: int = 3) -> dict:
    """Medians of ``WAVE_TABLE_METRICS`` per significant-wave-height bin x origin-depth bin
    (equal-width bins over the sampled ranges of a sweep with ``[waves]``; one depth bin when
    ``origin_depth`` is fixed), per variant, over the runs that did not diverge.

    Returns:
        ``{"hs_edges": [...] m, "origin_depth_edges": [...] m, "variants": {variant: {metric:
        [[median or None, ...] per depth bin] per Hs bin, "count": [[n, ...], ...]}}}``.
    """
    sc = result.spec.scenario
    hs = np.asarray(result.scenarios["wave_hs"], np.float64)
    depth = np.asarray(result.scenarios["wave_origin_depth"], np.float64)

    def edges(r, n):
        lo, hi = r
        return np.linspace(lo, hi, n + 1) if hi > lo else np.array([lo, hi])

    he, de = edges(sc.waves.hs, hs_bins), edges(sc.waves.origin_depth, depth_bins)
    ih = np.clip(np.searchsorted(he, hs, side="right") - 1, 0, len(he) - 2)
    idp = np.clip(np.searchsorted(de, depth, side="right") - 1, 0, len(de) - 2)
    out = {"hs_edges": he.tolist(), "origin_depth_edges": de.tolist(), "variants": {}}
    for v, m in result.metrics.items():
        ok = ~np.asarray(m["diverged"], bool)
        entry = {}
        for key in (*WAVE_TABLE_METRICS, "count"):
            table = []
            for a in range(len(he) - 1):
                row = []
                for b in range(len(de) - 1):
                    sel = ok & (ih == a) & (idp == b)
                    if key == "count":
                        row.append(int(sel.sum()))
                    else:
                        x = np.asarray(m[key], np.float64)[sel]
                        row.append(float(np.median(x)) if x.size else None)
                table.append(row)
            entry[key] = table
        out["variants"][v] = entry
    return out


def summarize(result: SweepResult) -> dict:
    """JSON-ready summary: per variant, failure counts and per-metric statistics.

    ``summary["variants"][v]``: ``n``, ``n_diverged``, ``n_nonfinite`` (with ``[waves]`` also
    ``n_above_surface``: runs kept whose vehicle was above the local sea surface at some step,
    ``SURFACE_METRICS`` of [`vcjax.sweep.run`][vcjax.sweep.run]) and, for every metric,
    ``mean``, ``std``, ``p5``, ``p50``, ``p95``, ``min``, ``max`` over the runs that did not
    diverge (``None`` where there are none); ``timing``
    ([`run_timing`][vcjax.sweep.results.run_timing]: ``compile_s``,
    ``run_s``, ``traj_steps_per_s``, ...). A sweep with ``[waves]`` also has ``waves``
    ([`wave_table`][vcjax.sweep.results.wave_table]: median errors per wave height and depth bin). A
    sweep stopped by
    SIGINT / SIGTERM also has
    ``"interrupted": true`` and ``num_scenarios_planned`` (``num_scenarios`` is then the number
    of scenarios that ran: the chunks completed).
    """
    out = {}
    for v, m in result.metrics.items():
        ok = ~m["diverged"].astype(bool)
        entry = {
            "n": int(ok.size),
            "n_diverged": int((~ok).sum()),
            "n_nonfinite": int(m["nonfinite"].astype(bool).sum()),
        }
        entry["metrics"] = {
            k: _stats(np.asarray(a, dtype=np.float64)[ok]) for k, a in m.items() if k not in FLAGS
        }
        if "above_surface_fraction" in m:  # a sea: runs that broached (of those kept)
            above = np.asarray(m["above_surface_fraction"], np.float64)[ok]
            entry["n_above_surface"] = int((above > 0).sum())
        if v in result.timing:
            entry["timing"] = result.timing[v]
        out[v] = entry
    summary = {
        "num_scenarios": int(result.index.size),
        "wall_s": round(result.wall_s, 3),
        "devices": result.devices,
        "spec": spec_to_dict(result.spec),
        "variants": out,
    }
    if "wave_hs" in result.scenarios:
        summary["waves"] = wave_table(result)
    if result.interrupted:  # only then: summaries of complete sweeps keep their keys
        summary["interrupted"] = True
        summary["num_scenarios_planned"] = int(result.spec.num_scenarios)
    return summary


def save_results(result: SweepResult, path: Path) -> Path:
    """Write ``result`` to an ``.npz`` file (no pickles).

    Keys: ``index``; ``scenario.<field>`` (see [`MCScenario`][vcjax.sweep.spec.MCScenario];
    ``model_factors`` columns are ``model_fields``; with ``[waves]`` also ``scenario.wave_hs``
    [m], ``scenario.wave_tp`` [s], ``scenario.wave_direction_deg`` [deg] and
    ``scenario.wave_origin_depth`` [m]); ``<variant>.<metric>``;
    ``<variant>.trace_e`` (n, P), ``<variant>.trace_xy`` (n, P, 2); ``trace_t``; ``spec_json``.
    """
    path = Path(path)
    arrays = {"index": result.index, "trace_t": result.trace_t}
    arrays["model_fields"] = np.array(result.spec.mc_config().model_fields, dtype=str)
    arrays["spec_json"] = np.array(json.dumps(spec_to_dict(result.spec)))
    meta = {"wall_s": result.wall_s, "devices": result.devices, "timing": result.timing}
    if result.interrupted:
        meta["interrupted"] = True
    arrays["meta_json"] = np.array(json.dumps(meta))
    for k, a in result.scenarios.items():
        arrays[f"scenario.{k}"] = a
    for v in result.metrics:
        for k, a in result.metrics[v].items():
            arrays[f"{v}.{k}"] = a
        for k, a in result.traces[v].items():
            arrays[f"{v}.trace_{k}"] = a
    from vcjax.runtime.outputs import save_npz_atomic

    return save_npz_atomic(path, **arrays)


def load_results(path: Path) -> SweepResult:
    """Inverse of [`save_results`][vcjax.sweep.results.save_results]."""
    with np.load(Path(path), allow_pickle=False) as z:
        spec = spec_from_dict(json.loads(str(z["spec_json"])))
        meta = json.loads(str(z["meta_json"]))
        scen = {k[9:]: z[k] for k in z.files if k.startswith("scenario.")}
        metrics, traces = {}, {}
        for v in spec.variants:
            keys = [k for k in z.files if k.startswith(f"{v}.")]
            metrics[v] = {k[len(v) + 1 :]: z[k] for k in keys if ".trace_" not in k}
            traces[v] = {k: z[f"{v}.trace_{k}"] for k in ("e", "xy")}
        return SweepResult(
            spec,
            z["index"],
            scen,
            metrics,
            traces,
            z["trace_t"],
            meta["wall_s"],
            meta["devices"],
            meta.get("timing", {}),
            bool(meta.get("interrupted", False)),
        )
