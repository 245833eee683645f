"""Several membranes coupled through chambers: two balloons under total-volume control against the
exact one-degree-of-freedom solution (snapmem.reference.two_balloons), and a gas chamber."""

import numpy as np
import pytest

from snapmem import build_scene
from snapmem.catalog.chambers import balloon_membrane
from snapmem.catalog.scenes import get_spec
from snapmem.continuation import ContinuationOptions, trace
from snapmem.continuation.switching import switch_at
from snapmem.model.chambers import Chamber, gas_energy
from snapmem.model.multi import MultiScene
from snapmem.reference.exact import balloon_extrema, balloon_pressure
from snapmem.reference.two_balloons import asymmetric_fold, balloon_volume, pair_stable, symmetric_bifurcations


def _pair(nodes, **options):
    """The symmetric branch through both BPs and the asymmetric half from the first BP to its fold
    (with the scene's default continuation options, unless ``options`` are given)."""
    scene = build_scene("two_balloons", nodes=nodes)
    branch = trace(scene, "volume", until={"stretch_max": 2.8}, options=ContinuationOptions(**options))
    (_, child), *_ = switch_at(scene, "volume", branch.critical_state(0),
                               options=ContinuationOptions(stop_at_first_limit=True, max_steps=200, **options))
    return branch, child


@pytest.fixture(scope="module")
def pairs():
    return {n: _pair(n) for n in (51, 101, 201)}


def test_bps_and_fold_match_the_exact_pair_converging_as_N_minus_2(pairs):
    exact_bps = symmetric_bifurcations()
    fold = asymmetric_fold()
    errors = []
    for n, (branch, child) in pairs.items():
        bps = branch.points
        assert list(bps["kind"]) == ["BP", "BP"]
        assert bool(bps["located"].all())
        lps = child.points[child.points["kind"] == "LP"]
        assert len(lps) == 1
        row = lps.iloc[0]
        errors.append([abs(bps["control"].iloc[i] / exact_bps[i][0] - 1) for i in range(2)]
                      + [abs(bps["pressure"].iloc[i] / exact_bps[i][1] - 1) for i in range(2)]
                      + [abs(row["control"] / fold[0] - 1), abs(row["pressure"] / fold[1] - 1)])
    errors = np.array(errors)                                   # (3 meshes, 6 quantities)
    assert np.all(errors[1] < 2e-3)                             # N = 101 within mesh error
    slopes = np.log(errors[0] / errors[2]) / np.log(201 / 51)
    assert np.all((slopes > 1.8) & (slopes < 2.3)), slopes


def test_asymmetric_branch_is_the_exact_pair_with_its_stability(pairs):
    branch, child = pairs[101]
    t = child.table
    assert t["stretch_1"].iloc[5] != pytest.approx(t["stretch_2"].iloc[5], rel=1e-3)     # left the symmetric branch
    # p(lam1) = p(lam2) = the branch's pressure, within the mesh error of the balloon curve
    for k in ("stretch_1", "stretch_2"):
        assert np.max(np.abs(balloon_pressure(t[k]) / t["pressure"] - 1)) < 2e-3
    # the total volume is the two balloons' and the table's volume_1 + volume_2
    assert np.allclose(t["volume"], t["volume_1"] + t["volume_2"], rtol=1e-12)
    assert np.allclose(t["volume"], t["control"], rtol=1e-9)
    # stability from p'(V1) + p'(V2) > 0, away from the fold (where it changes)
    fold_s = float(child.points["s"].iloc[0])
    away = t[np.abs(t["s"] - fold_s) > 0.1]
    exact = [pair_stable(a, b) for a, b in zip(away["stretch_1"], away["stretch_2"])]
    assert len(away) > 10 and list(away["stable"]) == exact
    # the symmetric branch: stable until the first BP, unstable (one mode) between them, stable after
    lam_max, lam_min = (lam for lam, _ in balloon_extrema()[:2])
    s = branch.table
    between = (s["stretch_1"] > lam_max * 1.01) & (s["stretch_1"] < lam_min * 0.99)
    outside = ((s["stretch_1"] < lam_max * 0.99) | (s["stretch_1"] > lam_min * 1.01)) & (s["s"] > 0)
    assert s["negative_eigs"].iloc[0] == -1             # at rest the membranes are slack: K is singular
    assert (s.loc[between, "negative_eigs"] == 1).all() and (s.loc[outside, "negative_eigs"] == 0).all()


def _gas_balloon(dead_volume, nodes=51):
    """One balloon on a gas reservoir of dead volume ``dead_volume`` [m^3]."""
    params = get_spec("two_balloons").resolve(nodes=nodes)
    balloon = balloon_membrane(params, (), 10.0, "balloon")
    return MultiScene([balloon], [Chamber("gas", (0,), dead_volume=dead_volume, p_atm=0.25)], name="gas_balloon")


def test_gas_chamber_obeys_the_gas_law_and_tends_to_pressure_and_volume_control():
    v_ref = float(balloon_volume(1.0))
    (lam_max, p_max), _ = balloon_extrema()[:2]
    # the same mesh under pressure control: its limit point
    p_lp = trace(build_scene("balloon", nodes=51), "pressure", options=ContinuationOptions(stop_at_first_limit=True)
                 ).limit_points()["pressure"].iloc[0]
    assert p_lp == pytest.approx(p_max, rel=1e-3)
    gaps = []
    for dead in (0.0, 1e4 * v_ref, 1e5 * v_ref):
        scene = _gas_balloon(dead)
        branch = trace(scene, "gas_amount", until={"stretch_max": 2.0})
        t = branch.table
        gas = (t["pressure"] + 0.25) * (t["volume"]) / t["gas_amount"] - 1        # (p + p_atm) V_c = n R T
        assert np.max(np.abs(gas)) < 1e-10
        assert np.allclose(t["volume"], t["volume_1"] + dead, rtol=1e-12)
        lps = branch.points[branch.points["kind"] == "LP"]
        if dead == 0.0:                       # a stiff gas: no snap, stable throughout (as under volume control)
            assert lps.empty and (t["negative_eigs"] == 0).all()
        else:                                 # a large reservoir: the pressure-controlled limit point
            assert len(lps) >= 1
            gaps.append(abs(lps["pressure"].iloc[0] - p_lp))
    assert gaps[1] < 0.5 * gaps[0] and gaps[1] < 1e-4 * p_lp, gaps


def test_gas_energy_is_stationary_at_the_gas_law():
    """-dE/dV of E = -nRT ln V + p_atm V is the gauge pressure nRT / V - p_atm."""
    amount, p_atm, v, h = 3.0, 0.25, 7.0, 1e-5
    dE = (gas_energy(v + h, amount, p_atm) - gas_energy(v - h, amount, p_atm)) / (2 * h)
    assert -dE == pytest.approx(amount / v - p_atm, rel=1e-9)


def test_bad_control_is_one_clear_error():
    from snapmem.errors import SnapmemError
    with pytest.raises(SnapmemError, match="gas"):
        trace(build_scene("two_balloons", nodes=11), "gas_amount")


def test_chamber_volume_fast_path_is_the_membranes_volume_and_load_derivative():
    """The chamber's volume and gradient from the nodes and the compiled kernel equal each
    membrane's Scene.volume and -dR/dp (the general path), on a deformed unequal pair."""
    scene = build_scene("two_balloons", nodes=21, R2=12.0)
    q = scene.reference_state()
    q[0::2] *= 1.0 + 0.1 * np.sin(np.arange(q[0::2].size))
    q[1::2] *= 0.9
    fast = scene.chamber_volume_and_gradient(q, 0)
    scene._swept = [False, False]
    general = scene.chamber_volume_and_gradient(q, 0)
    assert fast[0] == pytest.approx(general[0], rel=1e-13)
    assert np.allclose(fast[1], general[1], rtol=0, atol=1e-12 * np.abs(general[1]).max())
    parts = scene.split(q)
    assert general[0] == pytest.approx(sum(m.volume(p) for m, p in zip(scene.membranes, parts)), rel=1e-13)


def test_balloon_on_a_gas_reservoir_is_the_gas_chamber_scene(tmp_path):
    """``balloon --set chamber=gas --set gas_volume=V`` is one balloon on a gas chamber of dead
    volume V: its branch is the MultiScene's built by hand, it obeys the gas law, and the
    default ``chamber = pressure`` balloon is the plain scene with its parameters unchanged."""
    from snapmem.cli import main
    plain = build_scene("balloon", nodes=21)
    assert not isinstance(plain, MultiScene) and "chamber" not in plain.parameters
    dead = 1e4 * float(balloon_volume(1.0))
    scene = build_scene("balloon", nodes=51, chamber="gas", gas_volume=dead)
    assert isinstance(scene, MultiScene) and scene.parameters["gas_volume"] == dead
    t = trace(scene, "gas_amount", until={"stretch_max": 2.0}).table
    by_hand = trace(_gas_balloon(dead), "gas_amount", until={"stretch_max": 2.0}).table
    assert np.allclose(t["pressure"], by_hand["pressure"], rtol=1e-12, atol=0)
    assert np.max(np.abs((t["pressure"] + 0.25) * t["volume"] / t["gas_amount"] - 1)) < 1e-10
    out = tmp_path / "gas.csv"
    assert main(["trace", "balloon", "--set", "chamber=gas", "--set", f"gas_volume={dead}", "--set", "nodes=31",
                 "--control", "gas_amount", "--until", "stretch_max=2", "--out", str(out)]) == 0
    assert out.exists()
    from snapmem.errors import SnapmemError
    with pytest.raises(SnapmemError, match="gas sets the pressure"):
        build_scene("balloon", chamber="gas", pressure=0.01)


# ---------------------------------------------------------------------------------------------
# the adiabatic gas chamber: P V^gamma = C
def test_adiabatic_energy_gradient_and_hessian_by_finite_differences():
    """-dE/dV is the gauge pressure C / V^gamma - p_atm and d2E/dV2 the gas' stiffness, by central
    differences; -dV/dp (the compliance) is its inverse; at gamma = 1 the formulas are the isothermal ones."""
    from snapmem.model.chambers import gas_compliance, gas_pressure, gas_stiffness, gas_volume
    amount, p_atm, v = 3.0, 0.25, 7.0
    for gamma in (1.0, 1.4, 5.0 / 3.0):
        h = 1e-4 * v
        E = [gas_energy(v + k * h, amount, p_atm, gamma) for k in (-1, 0, 1)]
        assert -(E[2] - E[0]) / (2 * h) == pytest.approx(gas_pressure(v, amount, p_atm, gamma), rel=1e-7)
        assert (E[2] - 2 * E[1] + E[0]) / h ** 2 == pytest.approx(gas_stiffness(v, amount, p_atm, gamma), rel=1e-6)
        p = gas_pressure(v, amount, p_atm, gamma)
        assert gas_volume(p, amount, p_atm, gamma) == pytest.approx(v, rel=1e-14)
        assert gas_compliance(p, amount, p_atm, gamma) == pytest.approx(1 / gas_stiffness(v, amount, p_atm, gamma),
                                                                       rel=1e-13)
    near = 1.0 + 2.0 ** -30            # gamma -> 1: E - C / (gamma - 1) tends to the isothermal energy
    assert gas_energy(v, amount, p_atm, near) - amount / (near - 1) == pytest.approx(gas_energy(v, amount, p_atm),
                                                                                     abs=1e-5)


def test_adiabatic_chamber_jacobian_is_the_residuals_derivative():
    """The bordered Jacobian J = [[K, -G], [-G^T, -D]] of a balloon on an adiabatic reservoir
    against central differences of its residual, at a deformed state and a pressure off equilibrium."""
    from snapmem.continuation.problems import make_problem
    scene = build_scene("balloon", nodes=21, chamber="adiabatic", gas_volume=2 * float(balloon_volume(1.0)))
    pb = make_problem(scene, "gas_amount")
    x = pb.x_of(scene.reference_state(), {"pressure_1": 0.0} if "pressure_1" in scene.loads else None)
    x = x.copy()
    x[:-1] *= 1.0 + 0.05 * np.cos(np.arange(x.size - 1))
    x[-1] = 0.01
    lam = 0.3 * float(balloon_volume(1.0)) ** 1.4
    F, J = pb.evaluate(x, lam)
    dense = J.to_dense()
    h = 1e-6
    for j in range(0, x.size, 5):
        e = np.zeros(x.size)
        e[j] = h * max(abs(x[j]), 1.0)
        column = (pb.evaluate(x + e, lam, order=1)[0] - pb.evaluate(x - e, lam, order=1)[0]) / (2 * e[j])
        assert np.allclose(column, dense[:, j], rtol=1e-5, atol=1e-6 * np.abs(dense).max())
    dl = 1e-6 * lam
    fd = (pb.evaluate(x, lam + dl, order=1)[0] - pb.evaluate(x, lam - dl, order=1)[0]) / (2 * dl)
    assert np.allclose(fd, pb.dF_dlam(x, lam), rtol=1e-6, atol=1e-9 * np.abs(pb.dF_dlam(x, lam)).max())


def test_adiabatic_equilibria_obey_the_adiabat_and_tend_to_the_isothermal_gas():
    """Along a trace in C, (p + p_atm) V^gamma = C to solver tolerance; as gamma -> 1 the limit
    point tends to the isothermal chamber's, the gap falling as gamma - 1."""
    dead = 1e4 * float(balloon_volume(1.0))          # a reservoir large enough for a snap

    def first_lp(chamber, gamma=1.4):
        scene = build_scene("balloon", nodes=31, chamber=chamber, gas_volume=dead, gamma=gamma)
        branch = trace(scene, "gas_amount", until={"stretch_max": 2.0})
        return branch, branch.limit_points().iloc[0]

    branch, _ = first_lp("adiabatic")
    t = branch.table
    law = (t["pressure"] + 0.25) * t["volume"] ** 1.4 / t["gas_amount"] - 1
    assert np.max(np.abs(law)) < 1e-10 and len(t) > 10
    assert np.allclose(t["volume"], t["volume_1"] + dead, rtol=1e-12)
    _, iso = first_lp("gas")
    gaps = [abs(first_lp("adiabatic", 1.0 + e)[1]["volume_1"] / iso["volume_1"] - 1) for e in (1e-1, 1e-2, 1e-3)]
    assert gaps[0] > 1e-3                                  # the adiabatic gas is stiffer: a later snap
    ratios = [gaps[0] / gaps[1], gaps[1] / gaps[2]]
    assert all(7 < r < 13 for r in ratios), (gaps, ratios)


# ---------------------------------------------------------------------------------------------
# the balloon on a gas reservoir: the snap's cusp in the reservoir's size
@pytest.fixture(scope="module")
def pressure_branches():
    """The plain balloon traced in pressure past its pressure minimum, at N = 51 and 101."""
    return {n: trace(build_scene("balloon", nodes=n), "pressure", until={"stretch": 3.2}) for n in (51, 101)}


def test_reservoir_cusp_is_the_exact_one_converging_as_N_minus_2(pressure_branches):
    """The smallest reservoir with a snap (the limit points of the gas amount merge) against the
    exact 1-DOF balloon (snapmem.reference.gas_balloon), isothermal and adiabatic."""
    from snapmem.continuation.chambers import reservoir_folds
    from snapmem.reference.gas_balloon import cusp
    for gamma in (1.0, 1.4):
        exact = cusp(gamma=gamma)
        errors = [abs(reservoir_folds(pressure_branches[n], 0.25, gamma)["cusp"]["reservoir"] / exact["reservoir"] - 1)
                  for n in (51, 101)]
        assert errors[1] < 5e-4, errors
        order = np.log(errors[0] / errors[1]) / np.log(100 / 50)
        assert 1.8 < order < 2.2, (gamma, errors, order)
    assert cusp(gamma=1.4)["reservoir"] / cusp()["reservoir"] == pytest.approx(1.4, rel=0.01)   # ~ gamma


def test_gas_chamber_snaps_only_above_the_cusp_at_the_pressure_branch_limit_points(pressure_branches):
    """The gas-reservoir balloon traced in its gas amount: below the cusp's reservoir no limit
    point and stable throughout (as under volume control); above it the two limit points (the
    amount's maximum and minimum) are those the pressure branch gives (reservoir_limit_points) on
    the same mesh to 1e-7, and they approach the pressure maximum and minimum as the reservoir grows."""
    from snapmem.continuation.chambers import reservoir_folds, reservoir_limit_points
    branch = pressure_branches[51]
    found = reservoir_folds(branch, 0.25)["cusp"]
    pressure_extrema = [float(v) for v in branch.points["pressure"].iloc[:2]]
    gaps = []
    for ratio in (0.9, 1.5, 6.0):
        reservoir = ratio * found["reservoir"]
        scene = build_scene("balloon", nodes=51, chamber="gas", gas_volume=reservoir)
        t = trace(scene, "gas_amount", until={"stretch_max": 3.0})
        lps = t.limit_points()
        if ratio < 1:
            assert lps.empty and (t.table["negative_eigs"] == 0).all()
            continue
        pair = reservoir_limit_points(branch, reservoir, 0.25, cusp=found)
        assert list(lps["pressure"]) == pytest.approx([q["pressure"] for q in pair], rel=1e-7)
        assert list(lps["volume_1"]) == pytest.approx([q["volume"] for q in pair], rel=1e-7)
        assert lps["control"].iloc[0] > lps["control"].iloc[1]          # a maximum, then a minimum of the amount
        gaps.append(max(abs(lps["pressure"].iloc[k] / pressure_extrema[k] - 1) for k in range(2)))
    assert gaps[1] < 0.5 * gaps[0], gaps


@pytest.mark.slow
def test_gas_balloon_study_quick(tmp_path):
    """studies/gas_balloon.py --quick: the cusp converges at order 2 and the gas-chamber traces'
    limit points equal the pressure branch's."""
    import importlib.util
    from pathlib import Path
    import pandas as pd
    path = Path(__file__).resolve().parents[1] / "studies" / "gas_balloon.py"
    spec = importlib.util.spec_from_file_location("gas_balloon_study", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--quick", "--out", str(tmp_path)])
    cusps = pd.read_csv(tmp_path / "gas_balloon.csv")
    assert np.all((cusps["reservoir_order"].dropna() > 1.9) & (cusps["reservoir_order"].dropna() < 2.1))
    curve = pd.read_csv(tmp_path / "gas_balloon.curve.csv").dropna(subset=["traced_pressure"])
    assert len(curve) == 4 and np.allclose(curve["traced_pressure"], curve["pressure"], rtol=1e-7)
    assert (tmp_path / "gas_balloon.png").exists()


def test_switching_mirrors_the_second_half_of_an_identical_pair_only(pairs, monkeypatch):
    """At a BP of two identical balloons the half along -d is the exchange image of the half along
    +d (marked ``mirrored``, not computed): its limit point equals the computed half's to 1e-10.
    An unequal pair has no exchange symmetry."""
    import snapmem.continuation.switching as switching
    from snapmem.continuation.problems import make_problem
    scene = build_scene("two_balloons", nodes=51)
    branch, _ = pairs[51]
    options = ContinuationOptions(stop_at_first_limit=True, max_steps=200)
    halves = dict(switch_at(scene, "volume", branch.critical_state(0), options=options))
    mirrored = halves[-1]
    assert mirrored.stats["mirror_of"] == 1 and mirrored.table["mirrored"].all() and not halves[1].table["mirrored"].any()
    monkeypatch.setattr(switching, "_mirror_permutation", lambda *args: None)
    computed = dict(switch_at(scene, "volume", branch.critical_state(0), options=options))[-1]
    assert "mirror_of" not in computed.stats
    a, b = mirrored.limit_points().iloc[0], computed.limit_points().iloc[0]
    for column in ("control", "pressure", "volume_1", "volume_2", "stretch_1", "stretch_2"):
        assert a[column] == pytest.approx(b[column], rel=1e-10), column
    assert make_problem(build_scene("two_balloons", nodes=21, R2=10.2), "volume").exchange() is None
    assert make_problem(build_scene("two_balloons", nodes=21), "volume").exchange() is not None


# ---------------------------------------------------------------------------------------------
# the cost of two identical balloons: the symmetric states' evaluation by reduction, the fast options
def test_identical_membranes_in_the_same_state_are_evaluated_once_with_the_same_numbers():
    """Two identical balloons: the symmetric branch takes the second balloon's evaluation (energy,
    residual, stiffness, volume and gradient, domain, measures, local checks) from the first's
    (``reduced`` = True), the asymmetric half evaluates both (``reduced`` = False), and both
    traces are the full computation's (``reuse_identical`` = False) to the last bit. An unequal
    pair has no twins."""
    def traced(reuse):
        scene = build_scene("two_balloons", nodes=31)
        scene.reuse_identical = reuse
        branch = trace(scene, "volume", until={"stretch_max": 2.8})
        (_, half), *_ = switch_at(scene, "volume", branch.critical_state(0),
                                  options=ContinuationOptions(stop_at_first_limit=True, max_steps=200))
        return scene, branch, half

    scene, branch, half = traced(True)
    full_scene, full_branch, full_half = traced(False)
    assert scene.twin_of() == (None, 0) and full_scene.twin_of() == (None, None)
    assert scene.reduced_evaluations > 100 and full_scene.reduced_evaluations == 0
    assert branch.table["reduced"].all() and not half.table["reduced"].iloc[1:].any()
    assert "reduced" not in full_branch.table
    for reduced, full in ((branch, full_branch), (half, full_half)):
        for table, reference in ((reduced.table, full.table), (reduced.points, full.points)):
            assert list(table.columns.drop("reduced")) == list(reference.columns)
            for column in reference.columns:
                assert table[column].equals(reference[column]), column
        assert reduced.stats == full.stats
    unequal = build_scene("two_balloons", nodes=21, R2=10.2)
    assert unequal.twin_of() == (None, None)


def test_fast_options_locate_the_default_traces_points(pairs):
    """The scene's default options (``two_balloons``' continuation_defaults: 5 corrector iterations
    aimed at, not the generic 3, and a diverging corrector given up at once; the must-show run,
    studies/two_balloons.py timed_pair) take half the points and fewer corrector evaluations, and
    find the same BPs, fold and stability: the located points agree with the generic options'
    trace to 1e-11 relative at N = 101. Options the caller sets override the scene's."""
    import importlib.util
    from pathlib import Path
    from snapmem.continuation.options import SCENE_DEFAULTS, TARGET_ITERATIONS, resolve_options, resolved_target_iterations
    path = Path(__file__).resolve().parents[1] / "studies" / "two_balloons.py"
    spec = importlib.util.spec_from_file_location("two_balloons_study", path)
    study = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(study)
    scene = build_scene("two_balloons", nodes=21)
    assert resolved_target_iterations(ContinuationOptions(), scene) == 5
    assert resolved_target_iterations(ContinuationOptions(target_iterations=3), scene) == 3
    assert resolved_target_iterations(ContinuationOptions(), build_scene("balloon", nodes=21)) == TARGET_ITERATIONS
    assert resolve_options(ContinuationOptions(), scene).abandon_diverging is True
    assert resolve_options(ContinuationOptions(abandon_diverging=False), scene).abandon_diverging is False
    assert resolve_options(ContinuationOptions(), build_scene("balloon", nodes=21)) == ContinuationOptions(**SCENE_DEFAULTS)
    branch, child = _pair(101, **SCENE_DEFAULTS)
    fast, fast_child = study.timed_pair(101)
    default, default_child = pairs[101]
    assert len(default.table) == len(fast.table) and len(default_child.table) == len(fast_child.table)
    assert len(fast.table) + len(fast_child.table) < 0.6 * (len(branch.table) + len(child.table))
    # the diverging correctors given up at once: the same points as running them to the limit, cheaper
    patient, patient_child = _pair(101, abandon_diverging=False)
    assert patient_child.table["control"].equals(fast_child.table["control"])
    assert fast_child.stats["evaluations"] < patient_child.stats["evaluations"]
    assert list(fast.points["kind"]) == list(branch.points["kind"]) == ["BP", "BP"]
    # a pitchfork by the exchange symmetry: a = c = 0 to rounding at either BP location (the null
    # vector and the known tangent are made exactly antisymmetric and symmetric there), not only
    # where the eigenvalue iteration's rounding happens to be symmetric (c was 3e-6 here without)
    for half in (child, fast_child):
        switch = half.stats["switch"]
        assert abs(switch["a"]) < 1e-14 * abs(switch["b"]) and abs(switch["c"]) < 1e-14 * abs(switch["b"]), switch
    for column in ("control", "pressure", "stretch_1"):
        assert np.allclose(fast.points[column], branch.points[column], rtol=1e-11, atol=0), column
        assert fast_child.limit_points()[column].iloc[0] == pytest.approx(child.limit_points()[column].iloc[0],
                                                                          rel=1e-11), column
    end, fast_end = branch.table.iloc[-1], fast.table.iloc[-1]
    assert fast_end["stretch_max"] == pytest.approx(2.8, rel=1e-12) and end["control"] == pytest.approx(
        fast_end["control"], rel=1e-11)
    # stability along the fast half against the exact pair, as along the default one
    fold_s = float(fast_child.points["s"].iloc[0])
    away = fast_child.table[np.abs(fast_child.table["s"] - fold_s) > 0.1]
    assert len(away) > 5 and list(away["stable"]) == [pair_stable(a, b) for a, b in zip(away["stretch_1"],
                                                                                      away["stretch_2"])]


def test_bps_located_to_the_eigenvalues_rounding_are_brents_to_its_xtol(pairs, monkeypatch):
    """Locating a BP stops where the crossing eigenvalue is within rounding of |J|
    (ChamberProblem.crossing_rounding) instead of bisecting noise to Brent's xtol: the same BPs to
    1e-11 relative (control, pressure, each balloon's stretch), with fewer corrector evaluations."""
    from snapmem.continuation.chambers import ChamberProblem
    branch, _ = pairs[51]
    monkeypatch.setattr(ChamberProblem, "crossing_rounding", 0.0)
    to_xtol = trace(build_scene("two_balloons", nodes=51), "volume", until={"stretch_max": 2.8})
    assert list(to_xtol.points["kind"]) == list(branch.points["kind"]) == ["BP", "BP"]
    for column in ("control", "pressure", "stretch_1", "stretch_2"):
        assert np.allclose(branch.points[column], to_xtol.points[column], rtol=1e-11, atol=0), column
    assert branch.stats["evaluations"] < to_xtol.stats["evaluations"]
