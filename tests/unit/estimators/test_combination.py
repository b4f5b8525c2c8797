"""Logs of one robot combined into one estimate (wmrid.estimators.combination; ``wmrid identify LOG --given``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cliutil import assert_clean_error, wmrid

from wmrid.estimators.combination import SHARED_ALWAYS, Part, combine, given_weight, shared_names

BASE = ["m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2"]


def _covariance(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.standard_normal((n, n))
    scale = np.exp(rng.uniform(-2.0, 0.0, n))
    return np.outer(scale, scale) * (a @ a.T / n + 0.2 * np.eye(n))


def test_exact_covariances_combine_as_the_textbook_sum_of_information() -> None:
    """With covariances known exactly (dof None) the weights are their inverses: x = (C1^-1 + C2^-1)^-1 (C1^-1 x1 +
    C2^-1 x2) and Cov = (C1^-1 + C2^-1)^-1, to rounding."""
    rng = np.random.Generator(np.random.PCG64(3))
    c1, c2 = _covariance(rng, 5), _covariance(rng, 5)
    x1, x2 = rng.standard_normal(5), rng.standard_normal(5)
    everything = tuple(range(5))
    x, cov, dof, det = combine([Part(x1, c1, None, everything), Part(x2, c2, None, everything)], 5)
    i1, i2 = np.linalg.inv(c1), np.linalg.inv(c2)
    expected_cov = np.linalg.inv(i1 + i2)
    np.testing.assert_allclose(cov, expected_cov, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(x, expected_cov @ (i1 @ x1 + i2 @ x2), rtol=1e-9, atol=1e-12)
    assert dof is None
    assert det == everything


def test_fixed_weight_covariance_matches_a_monte_carlo() -> None:
    """Fixed weights from covariances with 9 degrees of freedom (their correlations shrunk), the second log determining
    only three of the five parameters: 4,000 draws of both estimates around the truth, combined, have the mean of
    the truth (within 4 standard errors) and each std within 5 % of the formula (the Monte Carlo's own spread on a
    std from 4,000 draws: 1.1 %)."""
    rng = np.random.Generator(np.random.PCG64(5))
    c1, c2 = _covariance(rng, 5), _covariance(rng, 5)
    truth = rng.standard_normal(5)
    parts = [Part(truth, c1, 9, tuple(range(5))), Part(truth, c2, 9, (0, 1, 2))]
    _, cov, _, _ = combine(parts, 5, weight_noise=False)
    l1, l2 = np.linalg.cholesky(c1), np.linalg.cholesky(c2[:3, :3])
    draws = []
    for _ in range(4000):
        x2 = truth.copy()
        x2[:3] += l2 @ rng.standard_normal(3)
        one = Part(truth + l1 @ rng.standard_normal(5), c1, 9, tuple(range(5)))
        draws.append(combine([one, Part(x2, c2, 9, (0, 1, 2))], 5, weight_noise=False)[0])
    draws = np.array(draws)
    std = np.sqrt(np.diag(cov))
    assert np.all(np.abs(draws.mean(axis=0) - truth) < 4 * std / np.sqrt(len(draws)))
    assert np.all(np.abs(draws.std(axis=0, ddof=1) / std - 1.0) < 0.05)


@pytest.mark.parametrize("steady", [False, True])
def test_weights_from_estimated_covariances_are_widened_enough(monkeypatch, steady: bool) -> None:
    """As in use: each log's covariance estimated on few degrees of freedom (a Wishart draw around the true one: 9
    and 14, as a 20 s and a 30 s log's jackknife), its weights made from that estimate, alone (its correlations
    shrunk) or scaling a steady weighting covariance (``steady``: the true one, 1.5 times too small, as the observer's
    Newey-West one can be).  Over 500 draws, the combination's variance against its mean reported variance:
    0.8-1.15 with the bootstrap's widening (measured on 4,000 draws and three covariance pairs, shrunk weights:
    0.90-1.01), while without a steady covariance the fixed-weight formula alone falls short by more than 1.2
    (measured: 1.25-1.55).  The Monte Carlo's own spread on a variance from 500 draws: 6.3 %; the widening's bootstrap
    is cut to 500 draws here to keep the test short."""
    import wmrid.estimators.combination as combination

    monkeypatch.setattr(combination, "WEIGHT_DRAWS", 500)
    rng = np.random.Generator(np.random.PCG64(11))
    n, dofs = 4, (9, 14)
    chol = [np.linalg.cholesky(_covariance(rng, n)) for _ in dofs]
    every = tuple(range(n))
    xs, widened, fixed = [], [], []
    for _ in range(500):
        parts = []
        for root, dof in zip(chol, dofs, strict=True):
            z = root @ rng.standard_normal((n, dof))
            weighting = root @ root.T / 1.5 if steady else None
            parts.append(Part(root @ rng.standard_normal(n), z @ z.T / dof, dof, every, weighting))
        x, cov, _, _ = combine(parts, n)
        xs.append(x)
        widened.append(np.diag(cov))
        fixed.append(np.diag(combine(parts, n, weight_noise=False)[1]))
    spread = np.var(np.array(xs), axis=0, ddof=1)
    ratio = spread / np.mean(widened, axis=0)
    assert np.all((ratio > 0.8) & (ratio < 1.15)), ratio
    if not steady:
        assert np.all(spread / np.mean(fixed, axis=0) > 1.2)


def test_degrees_of_freedom_by_welch_satterthwaite() -> None:
    """One log: its own degrees of freedom.  Two logs with the same covariance and 9 each: 18 (the variance is the
    sum of two equal independent shares).  A parameter only one log determines keeps that log's: the smallest is
    reported."""
    rng = np.random.Generator(np.random.PCG64(8))
    c = _covariance(rng, 4)
    x = np.zeros(4)
    every = tuple(range(4))
    assert combine([Part(x, c, 9, every)], 4)[2] == 9
    assert combine([Part(x, c, 9, every), Part(x, c, 9, every)], 4)[2] == 18
    diag = np.diag(np.diag(c))
    assert combine([Part(x, diag, 9, every), Part(x, diag, 30, (0, 1))], 4)[2] == 9


def test_a_parameter_no_log_determines_stays_undetermined() -> None:
    c = np.eye(3)
    x, cov, _, det = combine([Part(np.ones(3), c, 9, (0, 1))], 3)
    assert det == (0, 1)
    assert np.isnan(x[2])
    assert cov[2, 2] == np.inf
    assert np.isnan(cov[0, 2])


def test_only_what_means_the_same_is_combined() -> None:
    """The same friction model (the same base parameters): all of them; another (a log fitted without the casters'
    drag holds it in F_d): the inertia and V_c only."""
    with_drag = (*BASE, "D1", "D1dv", "D1w2")
    assert shared_names(BASE, BASE) == tuple(BASE)
    assert shared_names(BASE, with_drag) == SHARED_ALWAYS
    assert shared_names(with_drag, BASE) == SHARED_ALWAYS


def test_given_weight_is_the_inverse_when_exact() -> None:
    rng = np.random.Generator(np.random.PCG64(1))
    c = _covariance(rng, 4)
    np.testing.assert_allclose(given_weight(c, None), np.linalg.inv(c), rtol=1e-8)


def _simulate(path, seed: int) -> None:
    proc = wmrid("simulate", "-o", str(path), "--duration", "20", "--seed", str(seed), "--rate", "1000",
                 "--eta-noise", "0.05", "--tau-noise", "0.2")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()


def test_identify_given_combines_two_logs(tmp_path) -> None:
    """Two noisy 20 s logs of the paper robot: ``identify B --given A.json`` reports their combination (first
    warning naming A.json; every base parameter's std below the larger of the two logs' own, and on average below
    0.9 of B's, kept in diagnostics.combined.this_log; the truth within 4 std), the same numbers as the library's
    ``identify(B, given=A.json)``; a missing, unreadable or foreign --given file, or one in other effort units, is
    one line and exit 2, before the log is read."""
    import wmrid as lib

    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    _simulate(a, 1)
    _simulate(b, 2)
    first = tmp_path / "a.json"
    assert wmrid("identify", str(a), "--robot", "paper", "--format", "json", "-o", str(first)).returncode == 0
    proc = wmrid("identify", str(b), "--robot", "paper", "--given", str(first), "--format", "json")
    assert proc.returncode == 0, proc.stderr.decode()
    out = json.loads(proc.stdout)
    assert out["warnings"][0].startswith(f"combined with 1 earlier result ({first})")
    assert out["verdict"]["summary"].startswith("These logs determine")
    assert "combined with 1 earlier result's" in out["diagnostics"]["uncertainty"]["method"]
    own = out["diagnostics"]["combined"]["this_log"]
    theirs = json.loads(first.read_text())["parameters"]
    truth = json.loads((tmp_path / "b.csv.truth.json").read_text())["parameters"]
    ratios = []
    for name in BASE:
        value, std = out["parameters"][name]["value"], out["parameters"][name]["std"]
        assert std < max(own[name]["std"], theirs[name]["std"]), name
        assert abs(value - truth[name]) < 4 * std, name
        ratios.append(std / own[name]["std"])
    assert np.mean(ratios) < 0.9, ratios  # two logs alike: about 1 / sqrt(2) (measured 0.75)
    assert out["diagnostics"]["combined"]["results"][0]["parameters"] == BASE
    library = lib.identify(str(b), "paper", given=str(first))
    for name in BASE:
        assert library.parameters[name] == pytest.approx(
            (out["parameters"][name]["value"], out["parameters"][name]["std"]), rel=1e-9
        )
    missing = tmp_path / "none.json"
    assert_clean_error(wmrid("identify", str(b), "--robot", "paper", "--given", str(missing)), 2, str(missing))
    not_json = tmp_path / "plan.csv"
    not_json.write_text("t,v\n0,0\n")
    assert_clean_error(
        wmrid("identify", str(b), "--robot", "paper", "--given", str(not_json)), 2, str(not_json), "a saved result"
    )
    data = json.loads(first.read_text())
    data["effort_unit"] = "A"
    data["log"]["effort_unit"] = "A"
    amps = tmp_path / "amps.json"
    amps.write_text(json.dumps(data))
    assert_clean_error(wmrid("identify", str(b), "--robot", "paper", "--given", str(amps)), 2, str(amps), "same units")


def test_edge_cases_combine_without_error() -> None:
    """Fewer degrees of freedom than parameters (a jackknife of 2 segments: dof 1 for 4 parameters) combine without
    error (their correlations not trusted at all); a log known exactly leaves the others' degrees of freedom; a
    parameter only one log gives keeps that log's own std (nothing to widen)."""
    rng = np.random.Generator(np.random.PCG64(4))
    c = _covariance(rng, 4)
    every = tuple(range(4))
    _, cov, dof, _ = combine([Part(np.zeros(4), c, 1, every), Part(np.ones(4), c, 1, every)], 4)
    assert np.all(np.isfinite(cov))
    assert dof is not None
    assert combine([Part(np.zeros(4), c, 9, every), Part(np.ones(4), c, None, every)], 4)[2] >= 9
    _, alone, _, _ = combine([Part(np.zeros(4), c, 9, every), Part(np.ones(4), c, 9, ())], 4)
    np.testing.assert_allclose(alone, c, rtol=1e-12)


def test_a_methods_estimate_carries_the_std_it_reports(tmp_path) -> None:
    """A method other than the observer reports the observer's widening of the std (here a model-error scale); its
    estimate's covariance, which the JSON saves and --given combines, is that widened one too."""
    import wmrid as lib

    log = tmp_path / "a.csv"
    proc = wmrid("simulate", "-o", str(log), "--duration", "20", "--seed", "1", "--rate", "200",
                 "--eta-noise", "0.05", "--tau-noise", "0.2")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    result = lib.identify(str(log), "paper", method="idim")
    assert result.diagnostics.uncertainty.model_error.scale > 2
    np.testing.assert_allclose(result.estimate.cov, result.theta0_cov, rtol=1e-12)
    std = np.sqrt(np.diag(result.estimate.cov))[:8]
    assert std == pytest.approx([result.parameters[n][1] for n in BASE], rel=1e-9)
