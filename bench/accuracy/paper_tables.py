"""The paper's Tables 2 and 3 side by side with wmrid, as Markdown: ``python3 bench/accuracy/paper_tables.py``.

Paper columns are copied verbatim from Hoang & Kang (2015), Table 2 ("Estimated results of the
intermediate parameters") and Table 3 ("Estimated results of the dynamic parameters"); Table 3 has no
nominal column.  wmrid columns:

* nominal: Table 1's nominal column through Eqs. (10)-(14) (the result's ``nominal`` base parameters) and
  Eqs. (23)-(24) (:func:`intermediate`, checked against the observer's start, which is that);
* true: Table 1's CAD column plus the paper's friction F_v = diag(0.01, 0.015), F_d = diag(0.045, 0.04)
  through the same equations (the result's ``reference``);
* estimate: ``wmrid.identify`` on ``sample_logs/paper_sinusoid.parquet`` with the built-in ``paper`` robot, once
  with wmrid's defaults and once with the paper's own settings k = 1, alpha = 5000 (``wmrid.ObserverOptions``).

Error % is |estimate - true| / |true| * 100 (as in the paper), each against its own "true" column.
"gap left %" is (estimate - true) / (nominal - true) * 100: the share of the nominal start's error still
in the estimate at the end of the 40 s log (0 = converged, 100 = still at the start, above 100 = further
from the truth than the start).
Computed numbers are printed to 6 significant digits, and written to bench/results/paper_tables.json.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import wmrid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_results

LOG = ROOT / "sample_logs" / "paper_sinusoid.parquet"
#: The base parameters theta0 of Eq. (21), in order.
BASE = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")

# Hoang & Kang (2015), Table 2: parameter -> (nominal, true, estimated, error %), as printed.
PAPER_TABLE2 = {
    "theta11": ("0.923", "0.798475", "0.798614", "0.017"),
    "theta12": ("0.229", "0.246692", "0.246115", "0.234"),
    "theta13": ("0.147", "0.167752", "0.167936", "0.110"),
    "theta14": ("0.037", "0.051828", "0.051752", "0.147"),
    "theta15": ("0", "0.007985", "0.007985", "0.000"),
    "theta16": ("0", "0.002467", "0.003696", "0.135"),
    "theta17": ("0", "0.041807", "0.045775", "0.055"),
    "theta21": ("0.229", "0.246692", "0.246116", "0.233"),
    "theta22": ("0.923", "0.754828", "0.754931", "0.014"),
    "theta23": ("0.037", "0.051828", "0.051754", "0.143"),
    "theta24": ("0.147", "0.158583", "0.158748", "0.104"),
    "theta25": ("0", "0.002467", "0.002461", "0.243"),
    "theta26": ("0", "0.007549", "0.011326", "0.026"),
    "theta27": ("0", "0.040061", "0.041268", "0.065"),
}

# Hoang & Kang (2015), Table 3: parameter -> (true, estimated, error %), as printed (no nominal column).
PAPER_TABLE3 = {
    "m11": ("0.798475", "0.798614", "0.017"),
    "m12": ("0.246692", "0.246116", "0.234"),
    "m22": ("0.754828", "0.754931", "0.014"),
    "Vc": ("0.210090", "0.210279", "0.091"),
    "Fv1": ("0.010", "0.009999", "0.014"),
    "Fv2": ("0.015", "0.01501", "0.050"),
    "Fd1": ("0.045", "0.044992", "0.020"),
    "Fd2": ("0.040", "0.039997", "0.010"),
}

PAPER_K, PAPER_ALPHA = 1.0, 5000.0


def g6(x: float) -> str:
    return f"{x:.6g}"


def err_pct(est: float, true: float) -> str:
    return g6(abs(est - true) / abs(true) * 100.0)


def gap_left_pct(est: float, true: float, nominal: float) -> str:
    return "—" if nominal == true else g6((est - true) / (nominal - true) * 100.0)


def intermediate(base: dict[str, float], signs: tuple[int, int]) -> np.ndarray:
    """theta (2, 7) of Eqs. (23)-(24): row i is [m_i1, m_i2, m_i1 Vc, m_i2 Vc, m_i1 Fv1, m_i2 Fv2,
    m_i1 Fd1 s1 + m_i2 Fd2 s2] with m = [[m11, m12], [m12, m22]] and s the wheels' signs of the paper's form."""
    m = np.array([[base["m11"], base["m12"]], [base["m12"], base["m22"]]])
    s1, s2 = signs
    rows = []
    for mi1, mi2 in m:
        rows.append([mi1, mi2, mi1 * base["Vc"], mi2 * base["Vc"], mi1 * base["Fv1"], mi2 * base["Fv2"],
                     mi1 * base["Fd1"] * s1 + mi2 * base["Fd2"] * s2])  # fmt: skip
    return np.array(rows)


def markdown(header: list[str], rows: list[list[str]]) -> str:
    align = ["---"] + ["---:"] * (len(header) - 1)
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def main() -> None:
    robot = wmrid.load_robot("paper")
    log = wmrid.read_log(LOG)
    default = wmrid.identify(log, robot)
    paper_run = wmrid.identify(log, robot, observer=wmrid.ObserverOptions(k=PAPER_K, alpha=PAPER_ALPHA))
    form = default.form
    if paper_run.form != form or form.kind != "paper" or form.signs != (1, 1):
        raise SystemExit(f"expected the paper form with both wheels forward, got {form} / {paper_run.form}")

    base_nom = np.array([default.nominal[n] for n in BASE])
    base_true = np.array([default.reference[n] for n in BASE])
    theta_nom = intermediate(default.nominal, form.signs).ravel()
    theta_true = intermediate(default.reference, form.signs).ravel()
    start = np.asarray(default.observer_settings.theta_init).ravel()  # the observer starts from the nominal theta
    if not np.allclose(theta_nom, start, rtol=1e-12, atol=0):
        raise SystemExit(f"Eqs. (23)-(24) of the nominal set {theta_nom} differ from the observer's start {start}")
    theta_def = default.theta.ravel()
    theta_pap = paper_run.theta.ravel()

    print(
        f"Log: {LOG.relative_to(ROOT)} ({log.t.size} samples, {log.t[-1] - log.t[0]:g} s); robot: built-in "
        f"'paper'; regressor form: {form.kind} {form.signs}."
    )
    print()
    print(
        f"wmrid default: k = {default.observer_settings.k:g} 1/s, alpha = {default.observer_settings.alpha:g}, "
        f"torque hold {default.settings.torque_hold}.  Paper settings: k = {PAPER_K:g} 1/s, alpha = {PAPER_ALPHA:g}."
    )
    print()
    print("**Table 2** (intermediate parameters, Eqs. 23-24)")
    print()
    header = [
        "parameter",
        "paper nominal",
        "wmrid nominal",
        "paper true",
        "wmrid true",
        "paper estimate",
        "paper error %",
        "wmrid estimate",
        "wmrid error %",
        "wmrid k=1 α=5000 estimate",
        "k=1 α=5000 error %",
        "k=1 α=5000 gap left %",
    ]
    rows = []
    for j, name in enumerate(form.theta_names()):
        p_nom, p_true, p_est, p_err = PAPER_TABLE2[name]
        rows.append(
            [
                f"θ{name[-2:]}",
                p_nom,
                g6(theta_nom[j]),
                p_true,
                g6(theta_true[j]),
                p_est,
                p_err,
                g6(theta_def[j]),
                err_pct(theta_def[j], theta_true[j]),
                g6(theta_pap[j]),
                err_pct(theta_pap[j], theta_true[j]),
                gap_left_pct(theta_pap[j], theta_true[j], theta_nom[j]),
            ]
        )
    print(markdown(header, rows))
    print()
    print("**Table 3** (base parameters, Eq. 21)")
    print()
    header[1] = "paper nominal (not printed)"
    rows = []
    for j, name in enumerate(BASE):
        p_true, p_est, p_err = PAPER_TABLE3[name]
        est_d = default.parameters[name][0]
        est_p = paper_run.parameters[name][0]
        rows.append(
            [
                name,
                "—",
                g6(base_nom[j]),
                p_true,
                g6(base_true[j]),
                p_est,
                p_err,
                g6(est_d),
                err_pct(est_d, base_true[j]),
                g6(est_p),
                err_pct(est_p, base_true[j]),
                gap_left_pct(est_p, base_true[j], base_nom[j]),
            ]
        )
    print(markdown(header, rows))
    print()

    d_def, d_pap = default.diagnostics.to_dict(), paper_run.diagnostics.to_dict()
    worst_def = max(abs(default.parameters[n][0] / base_true[j] - 1) for j, n in enumerate(BASE))
    worst_pap = max(abs(paper_run.parameters[n][0] / base_true[j] - 1) for j, n in enumerate(BASE))
    gaps = [abs((paper_run.parameters[n][0] - base_true[j]) / (base_nom[j] - base_true[j])) for j, n in enumerate(BASE)]
    print(
        f"wmrid default (alpha = {default.observer_settings.alpha:g}): largest base-parameter error "
        f"{g6(100 * worst_def)} %; lambda_min(Gamma) at the end = {g6(d_def['lambda_min_gamma'])}; "
        f"{len(default.warnings)} warning(s)."
    )
    print()
    print(
        f"Paper settings (k = {PAPER_K:g}, alpha = {PAPER_ALPHA:g}): largest base-parameter error "
        f"{g6(100 * worst_pap)} %; "
        f"{g6(100 * min(gaps))}-{g6(100 * max(gaps))} % of the nominal start's error left after "
        f"{log.t[-1] - log.t[0]:g} s; lambda_min(Gamma) at the end = {g6(d_pap['lambda_min_gamma'])} "
        f"(data part {g6(d_pap['lambda_min_gamma'] - PAPER_ALPHA)}) against alpha = {PAPER_ALPHA:g}; "
        f"{len(paper_run.warnings)} warning(s)."
    )
    runs = {"default": default, "paper_settings": paper_run}
    write_results({
        "log": str(LOG.relative_to(ROOT)), "samples": int(log.t.size), "form": [form.kind, list(form.signs)],
        "settings": {k: {"k": r.observer_settings.k, "alpha": r.observer_settings.alpha} for k, r in runs.items()},
        "intermediate": {name: {"nominal": theta_nom[j], "true": theta_true[j], "default": theta_def[j],
                                "paper_settings": theta_pap[j]} for j, name in enumerate(form.theta_names())},
        "base": {name: {"nominal": base_nom[j], "true": base_true[j],
                        **{k: r.parameters[name][0] for k, r in runs.items()}} for j, name in enumerate(BASE)},
        "largest_error_percent": {"default": 100 * worst_def, "paper_settings": 100 * worst_pap},
        "gap_left_percent": {"min": 100 * min(gaps), "max": 100 * max(gaps)},
        "lambda_min_gamma": {k: r.diagnostics.lambda_min_gamma for k, r in runs.items()},
        "warnings": {k: len(r.warnings) for k, r in runs.items()},
    })  # fmt: skip


if __name__ == "__main__":
    main()
