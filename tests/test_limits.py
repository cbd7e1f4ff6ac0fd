"""Infeasible candidates explained: which limit binds, by how much, and the relaxation
that makes each feasible; a study without a feasible candidate names the nearest one and
the next steps."""

from __future__ import annotations

import dataclasses
import math

import pytest

from fabplan.errors import InputError
from fabplan.study.checks import (
    LIMIT_NAMES,
    binding_check,
    nearness,
    relaxation_text,
    violation,
)
from fabplan.study.run import judge_study, run_study
from fabplan.study.spec import parse_study

STUDY = """
[design]
surface = "hyperbolic-paraboloid"
[panels]
size = 2.0
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
max_molds = 3
[[candidates]]
net = "isogonal"
angle = 80
[[candidates]]
net = "linear-weingarten"
angle = 80
"""


@pytest.fixture(scope="module")
def judged():
    study = parse_study(STUDY)
    return study, run_study(study)


def test_every_check_has_its_margin_and_a_failed_one_its_relaxation(judged):
    _, result = judged
    for c in result.candidates:
        if c.failed:
            continue
        for check in c.checks:
            # a failed check has no margin to spare: negative, or none when it failed on
            # another ground than its measure (a solve that did not converge)
            assert check["ok"] or check["margin"] is None or check["margin"] < 0, check
            assert not check["ok"] or check["margin"] is None or check["margin"] >= 0, check
            if check["ok"] or check["limit"] == "max_sphere_residual":
                assert check["relax_to"] is None
            else:                    # the relaxed limit would be met by the measured value
                lower = check["limit"].startswith("min_")
                assert (check["relax_to"] <= check["measured"] if lower
                        else check["relax_to"] >= check["measured"])
        binding = binding_check(c.checks)
        assert binding is not None
        unrated = [k for k in c.checks if not k["ok"] and k["margin"] is None]
        assert binding is (unrated[0] if unrated else min(
            (k for k in c.checks if k["margin"] is not None), key=lambda k: k["margin"]))


def test_relaxing_the_limits_as_said_makes_the_nearest_candidate_feasible(judged):
    study, result = judged
    tight = dataclasses.replace(study, limits=dataclasses.replace(
        study.limits, max_deviation_mm=0.01, max_molds=1))
    strict = judge_study(tight, result.design, result.candidates)
    assert strict.recommended is None
    nearest = min((c for c in strict.candidates if not c.failed),
                  key=lambda c: nearness(c.checks, c.metrics["status"]))
    assert math.isfinite(violation(nearest.checks))
    assert f"The nearest is {nearest.name}" in strict.recommendation
    # the ranking counts the limits failed first: a nearest that ranks lower says so
    assert (f"(ranked {nearest.rank}:" in strict.recommendation) == (nearest.rank != 1)
    relax = relaxation_text(nearest.checks)
    assert relax and f"It would be feasible with {relax}" in strict.recommendation
    assert "Other ways: keep the net nearer the design" in strict.recommendation
    # judged again with the limits it names, the candidate is feasible
    relaxed = dict(tight.limits.__dict__)
    for check in nearest.checks:
        if not check["ok"]:
            relaxed[check["limit"]] = check["relax_to"]
    again = judge_study(dataclasses.replace(tight, limits=dataclasses.replace(tight.limits, **{
        k: relaxed[k] for k in ("max_deviation_mm", "max_molds", "mold_tolerance_mm")})),
        result.design, result.candidates)
    assert next(c for c in again.candidates if c.name == nearest.name).feasible


def test_every_infeasible_candidate_says_what_would_make_it_feasible_or_what_to_try(judged):
    """Each infeasible candidate's record and report verdict: the relaxation that makes it
    feasible, or, for a solve that did not converge (no limit relaxed would do), what to
    try instead."""
    from fabplan.study.records import study_record
    from fabplan.study.tables import candidate_facts

    study, result = judged
    tight = dataclasses.replace(study, limits=dataclasses.replace(
        study.limits, max_deviation_mm=0.01, max_molds=1))
    strict = judge_study(tight, result.design, result.candidates)
    records = {r["name"]: r for r in study_record(strict)["candidates"]}
    for c in strict.candidates:
        record = records[c.name]
        if c.failed or c.feasible:
            assert record["next_steps"] == [] or c.failed
            continue
        verdict, _ = candidate_facts(c, strict)
        assert record["relaxation"] and f"feasible with {record['relaxation']}" in verdict
        assert "a smaller panel size" in " ".join(record["next_steps"])
    # a solve that stopped short: nothing to relax, what to try said
    c = next(c for c in strict.candidates if not c.failed)
    stopped = {"limit": "max_sphere_residual", "bound": 1e-6, "measured": 0.003, "ok": False,
               "margin": -3000.0, "relax_to": None, "text": "the solve stopped"}
    stuck = dataclasses.replace(c, checks=[stopped, *c.checks], feasible=False)
    assert relaxation_text(stuck.checks) == ""
    verdict, _ = candidate_facts(stuck, strict)
    assert "To try: let the solve run longer (max_iterations)" in verdict


def test_a_stalled_solve_names_what_it_left_unmet_and_says_when_no_relaxation_exists(judged):
    """A solve that stopped short: its check names the worst unmet families; its advice
    comes from what the solve tried (a deviation continuation that found no net at any
    limit: another net type; several layout starts: not those again), and it is the only
    advice (the other checks measured no net yet)."""
    from fabplan.study.checks import next_steps
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    limits = dataclasses.replace(study.limits, max_molds=1)       # a mold check fails too
    metrics = {**c.metrics, "converged": False, "status": "stagnated",
               "unmet": {"sphere": 0.027, "edge-collapse": 0.07, "angle": 0.015,
                         "convex-quads": 0.044},
               "deviation_search": {"loosest_mm": 4320.0, "smallest_converged_mm": None}}
    checks = verdict(metrics, limits)
    solve = next(k for k in checks if k["limit"] == "max_sphere_residual")
    assert not solve["ok"] and solve["relax_to"] is None
    # its sphere residual may be within the bound: the check fails on the solve, and has
    # no margin left (it had a positive one, shown as a failed check beside a value within
    # its limit)
    if solve["measured"] is not None and solve["measured"] <= solve["bound"]:
        assert solve["margin"] is None
    within = verdict({**metrics, "sphere_residual_relative_max": 1e-15}, limits)
    solve = next(k for k in within if k["limit"] == "max_sphere_residual")
    assert not solve["ok"] and solve["margin"] is None and solve["measured"] == 1e-15
    # no check of an unfinished net says at which limit it would pass
    assert all(k["relax_to"] is None for k in checks + within)
    assert ("short on edge-collapse (0.07), convex-quads (0.044), sphere (0.027) and 1 more"
            in solve["text"])
    assert any(not k["ok"] and k["limit"] == "max_molds" for k in checks)
    assert relaxation_text(checks) == ""
    steps = next_steps(checks)
    assert len(steps) == 1 and steps[0].startswith("another net type") and "4,320 mm" in steps[0]
    # no continuation, several starts tried: the solve's advice does not ask for them again
    capped = {**metrics, "status": "iteration cap", "deviation_search": None}
    several = next_steps(verdict({**capped, "layout_starts": 5}, limits))
    assert several == ["let the solve run longer (max_iterations) or try another angle or panel "
                       "size: the net did not converge from 5 layout starts"]
    # one start: the general advice, which names several starts
    one = next_steps(verdict({**capped, "layout_starts": 1}, limits))
    assert len(one) == 1 and "layout_starts" in one[0]
    # a solve that stagnated before its iterations ran out: not more of them
    stalled = {**metrics, "deviation_search": None}
    assert next_steps(verdict({**stalled, "layout_starts": 5}, limits)) == [
        "another angle or panel size: the solve stagnated (it stopped making progress from 5 "
        "layout starts), so more iterations would not help"]
    one = next_steps(verdict({**stalled, "layout_starts": 1}, limits))
    assert "max_iterations" not in one[0] and "layout_starts" in one[0]
    # a net that met its constraints but crumpled: no longer solve, another lattice
    crumpled = next_steps(verdict({**metrics, "status": "crumpled", "unmet": {}}, limits))
    assert len(crumpled) == 1 and crumpled[0].startswith("another angle or panel size")
    assert "crumpled" in crumpled[0] and "max_iterations" not in crumpled[0]
    # a converged net names no unmet family and gets no solve advice
    done = verdict({**c.metrics, "unmet": {"angle": 0.3}}, limits)
    assert "short on" not in done[0]["text"] and done[0]["advice"] is None


def test_flat_panels_step_against_each_other_not_against_molds(judged):
    """A net of flat panels has no molds: its step check speaks of the panels."""
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    for flat in (True, False):
        molds = {**c.metrics["molds"], "all_panels_flat": flat, "panel_classes": None,
                 "max_panel_step_mm": 5.0, "panel_steps_over": 3}
        step = next(k for k in verdict({**c.metrics, "molds": molds}, study.limits)
                    if k["limit"] == "max_panel_step_mm")
        assert not step["ok"]
        assert step["text"].startswith("neighbouring panels step up to 5.00 mm apart at 3 "
                                       "shared edges" if flat else
                                       "the molds of neighbouring panels step up to 5.00 mm")


def test_a_net_within_the_deviation_limit_whose_boundary_panels_are_not_is_told_so(judged):
    """Where only the boundary panels as cut from their molds stand off the design beyond
    the limit, the advice is a smaller panel size, not a net type that glides (the net
    may glide already)."""
    from fabplan.study.checks import next_steps
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    limit = study.limits.max_deviation_mm
    for net, edge, told in ((0.5 * limit, 1.5 * limit, True), (1.2 * limit, 1.5 * limit, False)):
        metrics = {**c.metrics, "deviation_mm": {**c.metrics["deviation_mm"], "max": net},
                   "largest_deviation_mm": max(net, edge),
                   "boundary_panels": {**(c.metrics.get("boundary_panels") or {}),
                                       "deviation_max_mm": edge}}
        checks = verdict(metrics, study.limits)
        deviation = next(k for k in checks if k["limit"] == "max_deviation_mm")
        assert not deviation["ok"]
        steps = next_steps(checks)
        assert any(s.startswith("a smaller panel size: the net keeps within") for s in steps) == told
        assert any("a net type that glides" in s for s in steps) != told


def test_a_gliding_candidate_that_stalls_on_the_study_layout_is_solved_from_several_starts(
        judged, monkeypatch):
    """With one layout start, a gliding net that does not converge is solved from the
    other layout starts too (its first start the glide made already), the fairest kept;
    the S-net start of the nets that leave the design stays the first glide, whichever
    candidate makes it, and the study's layouts are left as they are."""
    import fabplan.layout.surface_layout as surface_layout
    from fabplan.layout.starts import MAX_STARTS
    from fabplan.study.candidate_solve import _CandidateSolve

    study, result = judged
    stalled = dataclasses.replace(result.candidates[0].net, status="stagnated")
    assert not stalled.converged
    asked = []

    def fairest(self, net_type, net_angle, starts=None, first_solved=None):
        asked.append((net_type, starts, first_solved))
        return "layout of the fairest", "net of the fairest"

    monkeypatch.setattr(surface_layout, "glide", lambda *a, **k: stalled)
    monkeypatch.setattr(_CandidateSolve, "fairest", fairest)
    said: list[str] = []
    for net_type in ("isogonal", "snet"):
        layouts = {"another key": "a layout"}
        solve = _CandidateSolve(study, result.design, dataclasses.replace(
            study.candidates[0], net=net_type), layouts, {}, said.append, 60.0, 1.0, None)
        net, layout = solve.gliding("layout of the study")
        assert (net, layout) == ("net of the fairest", "layout of the fairest")
        assert asked[-1] == (net_type, MAX_STARTS, ("layout of the study", stalled))
        assert layouts == {"another key": "a layout"}
    assert solve.starts == {solve.key: stalled}
    assert "stagnated from the study's layout: solved from other layout starts too" in said[0]
    # a converged glide is kept as it is
    monkeypatch.setattr(surface_layout, "glide", lambda *a, **k: result.candidates[0].net)
    assert result.candidates[0].net.converged
    assert solve.gliding("layout of the study")[0] is result.candidates[0].net
    assert len(asked) == 2


def test_the_recommendation_names_the_limit_that_binds_hardest(judged):
    _, result = judged
    if result.recommended is None:
        pytest.skip("no feasible candidate in this study")
    best = next(c for c in result.candidates if c.name == result.recommended)
    binding = binding_check(best.checks)
    from fabplan.study.checks import LIMIT_NAMES

    assert (f"The limit that binds hardest is the {LIMIT_NAMES[binding['limit']][0]}"
            in result.recommendation)


# ---------------------------------------------------------------------------- searches
def _point(search, value, *, feasible, cost):
    from fabplan.study.run import CandidateResult

    failed_check = {"limit": "max_deviation_mm", "bound": 10.0, "measured": 10.0 + cost,
                    "ok": False, "margin": -cost / 10.0, "relax_to": None, "text": ""}
    return CandidateResult(search.candidate(value), feasible=feasible, cost=cost,
                           metrics={"molds": {"count": 1}, "deviation_mm": {"max": 1.0},
                                    "largest_deviation_mm": 1.0, "status": "converged"},
                           checks=[] if feasible else [failed_check])


def test_a_search_refines_beside_its_best_point_within_its_budget():
    from fabplan.study.search import first_points, next_points, search_record
    from fabplan.study.spec import Search

    search = Search("lw", "linear-weingarten", "angle", 30.0, 60.0, budget=7)
    first = first_points(search)
    assert [c.angle for c in first] == [30.0, 40.0, 50.0, 60.0]
    costs = {30.0: 9.0, 40.0: 5.0, 50.0: 7.0, 60.0: 8.0}
    results = [_point(search, c.angle, feasible=True, cost=costs[c.angle]) for c in first]
    more = next_points(search, results)
    assert [c.angle for c in more] == [35.0, 45.0]
    # warm starts: each midpoint from the layout of the best point beside it
    assert all(c.start_angle == 40.0 for c in more)
    results += [_point(search, 35.0, feasible=True, cost=6.0),
                _point(search, 45.0, feasible=False, cost=1.0)]
    last = next_points(search, results)
    assert len(last) == 1 and last[0].angle in (37.5, 42.5)      # the budget's last solve
    results.append(_point(search, last[0].angle, feasible=True, cost=4.0))
    assert next_points(search, results) == []
    record = search_record(search, results)
    assert record["best"] == last[0].name and len(record["points"]) == 7
    assert record["feasible_range"] == [30.0, 60.0]


def test_a_search_guesses_its_next_round_from_the_points_measured_so_far():
    from fabplan.study.search import first_points, next_points
    from fabplan.study.spec import Search

    search = Search("lw", "linear-weingarten", "angle", 30.0, 60.0, budget=6)
    first = first_points(search)
    costs = {30.0: 9.0, 40.0: 5.0}
    measured = [_point(search, c.angle, feasible=True, cost=costs[c.angle]) for c in first[:2]]
    # 50 and 60 solved, not measured: 40 is the best so far, 50 its neighbour
    guess = next_points(search, measured, pending=(50.0, 60.0))
    assert [c.angle for c in guess] == [35.0, 45.0]
    # once measured, the round takes the same points where 40 stays the best
    every = measured + [_point(search, 50.0, feasible=True, cost=7.0),
                        _point(search, 60.0, feasible=False, cost=1.0)]
    assert next_points(search, every) == guess
    # pending points count against the budget
    assert next_points(Search("lw", "linear-weingarten", "angle", 30.0, 60.0, budget=4),
                       measured, pending=(50.0, 60.0)) == []


@pytest.mark.slow
def test_a_search_solved_ahead_of_its_round_gives_the_serial_run(monkeypatch):
    """The next round's points solved while the last round is measured (here always, as
    if the measuring never ended first): the same candidates and nets as a serial run.
    Where the guess is wrong nothing changes either: `next_points` is tested for that."""
    import numpy as np

    from fabplan.study import run as run_module
    from fabplan.study.background import BackgroundCandidates, background_processes

    if background_processes() == 0:
        pytest.skip("nothing is forked on this machine")
    study = parse_study(STUDY.replace('net = "linear-weingarten"\nangle = 80',
                                      'net = "isogonal"\nangle = { search = [60, 90], budget = 5 }'))
    serial = run_study(study)

    forks: list[tuple[str, bool]] = []

    class AlwaysBusy(BackgroundCandidates):
        """Busy whenever asked, with every candidate submitted measured: the guesses
        are the next round's points, whichever process ends first."""

        def is_busy(self) -> bool:
            return True

        def _fork(self, solved, twin, seconds, ahead=False):
            forks.append((solved.name, ahead))
            super()._fork(solved, twin, seconds, ahead)

        def measuring(self) -> set:
            while self._running:
                self._reap(wait=True)
            return set()

    ahead = []
    solve_ahead = run_module._solve_ahead

    def spy(*args):
        solve_ahead(*args)
        ahead.extend(c.name for c in args[-1])

    monkeypatch.setattr(run_module, "_solve_ahead", spy)
    forked = run_study(study, background=AlwaysBusy)
    later = [c.name for c in forked.candidates][5:]
    assert later and set(later) <= set(ahead)        # the last round was solved ahead
    # ... and measured ahead, once: its round took those measurings
    assert all((name, True) in forks for name in later)
    assert sorted(name for name, _ in forks) == sorted(c.name for c in forked.candidates)
    assert [c.name for c in forked.candidates] == [c.name for c in serial.candidates]
    for a, b in zip(serial.candidates, forked.candidates, strict=True):
        assert np.array_equal(a.net.mesh.vertices, b.net.mesh.vertices), a.name
        assert a.metrics["molds"] == b.metrics["molds"], a.name
        assert (a.feasible, a.cost) == (b.feasible, b.cost), a.name
    assert forked.recommended == serial.recommended


def test_a_solve_measured_ahead_is_taken_once_or_dropped_without_a_trace(monkeypatch, tmp_path):
    """A solve measured ahead of its round: not counted as busy; dropped (finished or
    still running, halfway through its files), it leaves no candidate, file (in the
    temporary folder either), line or process; submitted, its process is taken instead
    of a new one, with the measurements the run makes here; a twin found by the round
    has it measured again."""
    import os
    import tempfile
    import time

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    from fabplan.study.background import BackgroundCandidates, background_processes
    from fabplan.study.run import fabricate_candidate, prepare_design, solve_candidate

    if background_processes() == 0:
        pytest.skip("nothing is forked on this machine")
    study = parse_study(STUDY)
    quiet = lambda message: None                                     # noqa: E731
    design, baseline = prepare_design(study, quiet)
    candidate = study.candidates[0]
    solved = solve_candidate(study, design, candidate, {(90.0, study.panel_size): baseline}, {},
                             quiet)
    lines: list[str] = []
    done: list = []
    helper = BackgroundCandidates(study, design, lines.append, files=True, done=done.append)

    def gone(pid: int) -> bool:
        try:
            os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            return True
        return False

    helper.measure_ahead(solved)
    (job,) = helper._running
    assert job.ahead and not helper.is_busy() and helper.measuring() == set()
    deadline = time.monotonic() + 300
    while helper._running and time.monotonic() < deadline:      # measured to the end
        time.sleep(0.05)
        helper.is_busy()
    assert helper._finished_ahead == [job] and job.path.is_file()
    folder = job.path.parent
    helper.drop_ahead()
    assert not folder.exists() and gone(job.pid)
    assert helper.collect() == {} and helper.made_files == {} and not lines and not done

    helper.measure_ahead(solved)           # dropped while it runs
    (job,) = helper._running
    helper.drop_ahead()
    assert not helper._running and gone(job.pid) and not job.path.parent.exists()

    helper.measure_ahead(solved)           # dropped halfway through its files
    (job,) = helper._running
    scratch = job.path.with_suffix(".tmp")
    deadline = time.monotonic() + 300
    begun = False          # seen once: the job may finish and move them on at any moment
    while not begun and time.monotonic() < deadline:
        begun = any(p.is_file() for p in scratch.rglob("*"))
        time.sleep(0.01)
    assert begun
    helper.drop_ahead()
    assert gone(job.pid) and list(tmp_path.iterdir()) == []

    helper.measure_ahead(solved)           # taken while it runs
    started = [job.pid for job in helper._running]
    helper.submit(solved, None, 1e6)
    assert [job.pid for job in helper._running] == started and helper.is_busy()
    measured = helper.collect()[candidate.name]
    here = fabricate_candidate(study, design, solved, None, quiet)
    assert measured.metrics["molds"] == here.metrics["molds"]
    assert 1e6 <= measured.metrics["seconds"]["total"] < 1e6 + 600
    assert set(helper.made_files) == {candidate.name} and done == [measured] and lines

    helper.measure_ahead(solved)           # a twin after all: measured again, with it
    (job,) = helper._running
    helper.submit(solved, measured, 0.0)
    assert gone(job.pid) and [j.pid for j in helper._running] != [job.pid]
    assert not any(j.ahead for j in helper._running)
    helper.collect()
    assert len(done) == 2 and not helper._running and not helper._finished_ahead
    assert list(tmp_path.iterdir()) == []


def test_a_search_without_a_feasible_point_refines_beside_the_least_infeasible():
    from fabplan.study.search import first_points, next_points
    from fabplan.study.spec import Search

    search = Search("r", "const-radius", "radius", 10.0, 40.0, budget=6)
    first = first_points(search)
    excess = {10.0: 5.0, 20.0: 3.0, 30.0: 0.5, 40.0: 2.0}
    results = [_point(search, c.radius, feasible=False, cost=excess[c.radius]) for c in first]
    assert sorted(c.radius for c in next_points(search, results)) == [25.0, 35.0]


@pytest.mark.slow
def test_a_study_searches_an_angle_and_reports_it(tmp_path):
    import json

    from fabplan.study.report import write_study

    text = STUDY.replace('net = "linear-weingarten"\nangle = 80',
                         'net = "isogonal"\nangle = { search = [60, 90], budget = 5 }')
    study = parse_study(text)
    assert [s.name for s in study.searches] == ["isogonal"]
    result = run_study(study)
    names = [c.name for c in result.candidates]
    # the fixed candidate at 80 deg is the search's point there: solved once
    assert names[:5] == ["baseline", "isogonal-80", "isogonal-60", "isogonal-70", "isogonal-90"]
    assert len(names) == len(set(names)) == 6
    write_study(result, tmp_path / "out", pdf=False)
    record = json.loads((tmp_path / "out" / "study.json").read_text())
    (search,) = record["searches"]
    assert 4 <= len(search["points"]) <= 5
    assert all(60 <= p["value"] <= 90 for p in search["points"])
    feasible = [p for p in search["points"] if p["feasible"]]
    if feasible:
        assert search["best"] == min(feasible, key=lambda p: p["cost"])["candidate"]
    page = (tmp_path / "out" / "report.html").read_text()
    assert 'id="search-0"' in page and "Search: isogonal" in page


def test_boundary_panels_on_molds_of_their_own_are_not_said_to_be_cut_from_the_nets():
    """"110 boundary panels ..., each cut from a mold of the net's panels ..., 38 panels
    on a mold of its own" said two things of the 38."""
    from fabplan.study.tables import _boundary_text

    record = {"count": 110, "own_molds": 38, "flat": 72, "step_max_mm": 118.55,
              "deviation_max_mm": 290.2}
    text = _boundary_text(record)
    assert "each" not in text and "38 on molds of their own, the others cut from a mold" in text
    assert "each cut from a mold" in _boundary_text({**record, "own_molds": 0})
    assert "1 on a mold of its own" in _boundary_text({**record, "own_molds": 1})


def test_a_char_conjugate_net_on_a_partly_saddle_shaped_design_is_told_to_trim_it():
    """A characteristic conjugate net exists only where the Gaussian curvature is
    positive: a torus run past its parabolic lines got "a smaller panel size" for its
    290 mm boundary panels, which no panel size cures."""
    from fabplan.design.load import load_design
    from fabplan.study.candidate_measure import anticlastic_share
    from fabplan.study.verdict import _deviation_advice

    assert anticlastic_share(load_design("hyperbolic-paraboloid")) > 0.99
    assert anticlastic_share(load_design("paraboloid")) < 0.01
    limits = parse_study(STUDY).limits
    bound = limits.max_deviation_mm
    near = {"design_anticlastic": 0.08}
    assert "8 % of it is saddle-shaped" in _deviation_advice(near, limits, 0.5 * bound, 4 * bound)
    # a synclastic design: the boundary panels' advice, as before
    assert _deviation_advice({"design_anticlastic": 0.0}, limits, 0.5 * bound,
                             4 * bound).startswith("a smaller panel size")
    assert _deviation_advice({}, limits, 2 * bound, None) is None


def test_strips_that_twist_past_the_limit_fail_as_the_strips_command_says(judged):
    """The study's lamella strips are held to the twist `fabplan strips` holds them to:
    a study recommended a net whose own reproduce.sh then stopped on strips twisting
    99 deg/m (the strips command's default limit is 30)."""
    from fabplan.fabricate.limits import DEFAULT_MAX_TWIST_DEG_PER_M
    from fabplan.study.verdict import verdict

    study, result = judged
    assert study.limits.max_twist_deg_per_m == DEFAULT_MAX_TWIST_DEG_PER_M
    c = next(c for c in result.candidates if not c.failed)
    twisted = {**c.metrics, "strips": {"max_twist_deg_per_m": 99.0, "sheets": 3}}
    twist = next(k for k in verdict(twisted, study.limits) if k["limit"] == "max_twist_deg_per_m")
    assert not twist["ok"] and twist["relax_to"] == 99.0 and "99.0 deg/m" in twist["text"]
    looser = dataclasses.replace(study.limits, max_twist_deg_per_m=120.0)
    assert next(k for k in verdict(twisted, looser) if k["limit"] == "max_twist_deg_per_m")["ok"]
    # a candidate kept from before the twist was measured is not judged on it
    kept = {**c.metrics, "strips": {"sheets": 3}}
    assert all(k["limit"] != "max_twist_deg_per_m" for k in verdict(kept, study.limits))
    # the limit is read from the study file, and a bad one refused with its key named
    assert parse_study(STUDY.replace("max_molds = 3", "max_molds = 3\nmax_twist_deg_per_m = 12")
                       ).limits.max_twist_deg_per_m == 12.0
    with pytest.raises(InputError, match="max_twist_deg_per_m"):
        parse_study(STUDY.replace("max_molds = 3", "max_molds = 3\nmax_twist_deg_per_m = 0"))


def _failed(limit: str, bound: float, measured: float) -> dict:
    """A failed check as `fabplan.study.checks.check` makes it."""
    from fabplan.study.checks import check

    return check(limit, bound, measured, False, f"{limit} {measured}")


def test_the_nearest_candidate_is_the_one_least_many_times_over_its_limits():
    """A net twelve times the deviation limit off the design, its molds stepping thirty
    times the limit, is farther from feasible than a net on the design whose panels are
    forty times the tolerance off their molds: the gap and the step between the molds are
    one failure, and each limit counts by how many times it is missed, not by how far."""
    off_design = [_failed("max_deviation_mm", 150.0, 1805.4),
                  _failed("max_panel_step_mm", 2.0, 60.3)]
    on_design = [_failed("mold_tolerance_mm", 1.0, 43.1), _failed("max_panel_step_mm", 2.0, 83.2),
                 _failed("max_kink_deg", 10.0, 13.1)]
    assert violation(on_design) < violation(off_design)
    assert violation(on_design) == pytest.approx(math.log(43.1) + math.log(1.31))
    # each limit once: the step alone counts as much as with its gap beside it when larger
    assert violation(on_design[1:2]) == pytest.approx(math.log(41.6))
    # a smallest value missed counts by how many times too small it is
    assert violation([_failed("min_coverage", 0.9, 0.45)]) == pytest.approx(math.log(2.0))
    assert violation([_failed("min_coverage", 0.9, 0.0)]) == math.inf
    # nothing failed: feasible
    assert violation([]) == 0.0


def test_panels_that_fit_no_mold_are_told_the_panel_sizes_at_which_they_might(judged):
    """The advice on a failed mold gap or step names the panel sizes at which both would
    be within their limits, were they to shrink with the square of the size (at best) or
    the size itself (at worst), and the panels that makes; a step at the boundary panels,
    whose slivers come at every size, is named and not counted; no size without the
    candidate's panel size, no advice when the molds pass."""
    import re

    from fabplan.study.checks import advised_panel_size, next_steps
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    limits = study.limits
    gap, step = 9.0 * limits.mold_tolerance_mm, 30.0 * limits.panel_step_limit_mm
    molds = {**c.metrics["molds"], "failures": 7, "max_deviation_mm": gap,
             "max_panel_step_mm": step, "panel_steps_over": 4}
    metrics = {**c.metrics, "molds": molds, "boundary_panels": None}

    def sizes(checks):
        sized = [s for s in next_steps(checks) if "a smaller panel size (now 2 m" in s]
        assert len(sized) == 1                     # the gap and the step say it once
        found = re.search(r"so ([\d.]+) m \(([\d,]+) panels\) were (?:they|it) to shrink with "
                          r"the square of the panel size, ([\d.]+) m \(([\d,]+) panels\) were "
                          r"(?:they|it) to shrink in proportion", sized[0])
        assert found, sized[0]
        best, best_n, last, last_n = found.groups()
        return float(best), int(best_n.replace(",", "")), float(last), \
            int(last_n.replace(",", "")), sized[0]

    checks = verdict(metrics, limits, panel_size=2.0, units="m")
    best, best_n, last, last_n, _ = sizes(checks)
    assert last < best < 2.0
    assert advised_panel_size(checks) == best            # the first to try
    for measured, bound in ((gap, limits.mold_tolerance_mm), (step, limits.panel_step_limit_mm)):
        assert measured * (best / 2.0) ** 2 <= bound and measured * last / 2.0 <= bound
    assert best > 0.9 * 2.0 / math.sqrt(30.0) and last > 0.9 * 2.0 / 30.0
    assert c.metrics["panels"] * (2.0 / best) ** 2 <= best_n < last_n
    # the largest step at the boundary panels: named, and the sizes from the gap alone
    edge = {**metrics, "boundary_panels": {"step_max_mm": step}}
    best, _, last, _, text = sizes(verdict(edge, limits, panel_size=2.0, units="m"))
    assert "the largest step is at the boundary panels" in text
    assert "the largest gap is up to 9 times its limit" in text
    assert best == pytest.approx(2.0 / 3.0, rel=0.02) and last == pytest.approx(2.0 / 9.0, rel=0.02)
    # without the panel size, the general word; with molds that pass, no advice
    assert not any("now 2 m" in s for s in next_steps(verdict(metrics, limits)))
    fine = verdict(c.metrics, dataclasses.replace(limits, mold_tolerance_mm=1e3),
                   panel_size=2.0, units="m")
    assert all(k["advice"] is None for k in fine if k["limit"] in ("mold_tolerance_mm",
                                                                   "max_panel_step_mm"))


def test_the_nearest_is_a_net_on_the_design_and_none_is_named_when_no_solve_gave_a_net(judged):
    """A study without a feasible candidate names as nearest a net on the design before
    one that met its constraints only off it, however little that one misses; when no
    solve gave a net it names none (the cheapest unfinished net would mislead) and says
    what to try."""
    from fabplan.study.ranking import recommend

    study, result = judged
    done = [c for c in result.candidates if not c.failed][:2]
    assert len(done) == 2

    def as_(c, status, checks, rank):
        return dataclasses.replace(c, feasible=False, checks=checks, rank=rank,
                                   metrics={**c.metrics, "status": status},
                                   reasons=[f"reason of {c.name}"])

    gap = [_failed("mold_tolerance_mm", 1.0, 40.0)]
    off = [_failed("max_deviation_mm", 150.0, 160.0)]
    on_design, off_design = as_(done[0], "converged", gap, 2), as_(done[1], "off-design", off, 1)
    _, text = recommend([off_design, on_design], study)
    assert f"The nearest is {done[0].name}" in text and (
        "(ranked 2: the ranking counts the limits failed first; this is the net on the design "
        "the least many times over its limits)") in text
    assert "only off" not in text
    # only nets off the design: the nearest of them, said to be off it
    _, text = recommend([off_design], study)
    assert f"The nearest is {done[1].name}" in text and "met its constraints only off it" in text
    # no net at all: none is named
    stuck = [{**_failed("max_sphere_residual", 1e-6, 1e-3), "margin": None,
              "advice": "another net type"}]
    _, text = recommend([as_(c, "stagnated", stuck, i + 1) for i, c in enumerate(done)], study)
    assert "none is near" in text and "The nearest" not in text
    assert "To try: another net type." in text
    # the same step for several candidates, for reasons of their own: said once, without
    retry = "let the solve run longer: the net did not converge from {} layout starts"
    stuck = [[{**stuck[0], "advice": retry.format(n)}] for n in (4, 5)]
    _, text = recommend([as_(c, "stagnated", k, i + 1)
                         for i, (c, k) in enumerate(zip(done, stuck, strict=True))], study)
    assert "To try: let the solve run longer." in text
    # a step for some of them names those it is for
    other = [{**stuck[0][0], "advice": "another net type"}]
    _, text = recommend([as_(done[0], "stagnated", stuck[0], 1),
                         as_(done[1], "stagnated", other, 2)], study)
    assert (f"To try: let the solve run longer: the net did not converge from 4 layout starts "
            f"(for {done[0].name}); another net type (for {done[1].name}).") in text


def test_the_design_bend_radius_is_that_of_its_most_curved_part():
    """On a cylinder of radius 2 the design bends with radius 2; a plane does not bend."""
    import numpy as np

    from fabplan.design.mesh_surface import DesignSurface
    from fabplan.study.candidate_measure import bend_radius

    def grid(height):
        u, v = np.meshgrid(np.linspace(-1.0, 1.0, 41), np.linspace(0.0, 3.0, 41), indexing="ij")
        X = np.column_stack([*height(u.ravel(), v.ravel())])
        i = np.arange(40)[:, None] * 41 + np.arange(40)[None, :]
        quads = np.stack([i, i + 41, i + 42, i + 1], axis=-1).reshape(-1, 4)
        return DesignSurface(X, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))

    cylinder = grid(lambda u, v: (2.0 * np.sin(u), v, 2.0 * np.cos(u)))
    assert bend_radius(cylinder) == pytest.approx(2.0, rel=0.05)
    assert bend_radius(grid(lambda u, v: (u, v, 0.0 * u))) == math.inf


def test_panels_that_span_much_of_the_design_are_told_the_size_that_would_not(judged):
    """A kink over its limit where the design's own curvature turns a panel by more than
    the limit names the panel size that spans the limit; a solve that gave no net on a
    design a panel spans more than 30 deg of names the size that spans 30 deg first; no
    size where the design bends gently."""
    import re

    from fabplan.study.checks import advised_panel_size, next_steps
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    limits = dataclasses.replace(study.limits, max_kink_deg=10.0)
    sharp = {**c.metrics, "design_bend_radius": 1.0, "kink_deg": {**c.metrics["kink_deg"],
                                                                   "max": 40.0}}

    def named_size(checks, limit):
        kink = next(k for k in checks if k["limit"] == limit)
        found = re.search(r"at most about ([\d.]+) m \(now 2 m\)", kink["advice"] or "")
        return None if found is None else float(found.group(1))

    checks = verdict(sharp, limits, panel_size=2.0, units="m")
    size = named_size(checks, "max_kink_deg")
    assert size is not None and math.degrees(size / 1.0) <= 10.0 < math.degrees(1.1 * size)
    assert advised_panel_size(checks) == size          # what the study lays out to check
    gentle = {**sharp, "design_bend_radius": 100.0}
    assert named_size(verdict(gentle, limits, panel_size=2.0, units="m"), "max_kink_deg") is None
    # a solve that gave no net
    stuck = {**sharp, "converged": False, "status": "stagnated", "unmet": {"sphere": 0.1},
             "deviation_search": None, "layout_starts": 1}
    checks = verdict(stuck, limits, panel_size=2.0, units="m")
    size = named_size(checks, "max_sphere_residual")
    assert size is not None and math.degrees(size) <= 30.0 < math.degrees(1.1 * size)
    assert advised_panel_size(checks) == size
    steps = next_steps(checks)
    assert len(steps) == 1 and steps[0].startswith("a smaller panel size, at most about")
    assert "layout_starts" in steps[0]                 # the retry advice follows it
    assert named_size(verdict({**stuck, "design_bend_radius": 100.0}, limits, panel_size=2.0,
                              units="m"), "max_sphere_residual") is None


def test_a_failed_solve_within_its_residual_bound_says_why_in_the_check_table(judged):
    """The check table's row of a solve that gave no buildable net shows, beside a residual
    within the bound, why it failed ("2.2e-12 ... NO" read as a contradiction)."""
    from fabplan.study.tables import check_rows
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    stuck = {**c.metrics, "converged": False, "status": "crumpled", "unmet": {},
             "sphere_residual_relative_max": 2.2e-12}
    rows = check_rows(dataclasses.replace(c, checks=verdict(stuck, study.limits)))
    solve = next(r for r in rows if r[0] == LIMIT_NAMES["max_sphere_residual"][0])
    assert solve[3] == "NO" and solve[1].endswith("(no buildable net)")
    fine = next(r for r in check_rows(c) if r[0] == LIMIT_NAMES["max_sphere_residual"][0])
    assert fine[1].endswith("(no buildable net)") == (fine[3] == "NO")


def test_converged_nets_over_a_tightened_residual_are_nets_not_failed_solves(judged):
    """A converged net whose sphere residual is over a tightened limit gave a net: the
    study names its nearest (none is "no buildable net"), and the check table shows its
    residual without saying it gave none."""
    from fabplan.study.tables import check_rows

    study, result = judged
    tight = dataclasses.replace(study, limits=dataclasses.replace(
        study.limits, max_sphere_residual=1e-30))
    strict = judge_study(tight, result.design, result.candidates)
    converged = [c for c in strict.candidates if not c.failed and c.metrics["converged"]]
    assert converged and strict.recommended is None
    assert "The nearest is" in strict.recommendation and "none is near" not in strict.recommendation
    for c in converged:
        assert nearness(c.checks, c.metrics["status"])[0] == 0
        row = next(r for r in check_rows(c) if r[0] == LIMIT_NAMES["max_sphere_residual"][0])
        assert row[3] == "NO" and "no buildable net" not in row[1]


def test_advice_is_given_on_failed_checks_only(judged):
    """A kink within its limit on a sharply curved design, and a mold gap within its
    tolerance beside a failed step, carry no advice; a failed step whose limit is set
    apart from the tolerance asks for that limit to be larger."""
    from fabplan.study.verdict import verdict

    study, result = judged
    c = next(c for c in result.candidates if not c.failed)
    limits = dataclasses.replace(study.limits, max_kink_deg=90.0, max_panel_step_mm=1.0)
    molds = {**c.metrics["molds"], "failures": 0, "max_deviation_mm": 0.5,
             "max_panel_step_mm": 9.0, "panel_steps_over": 2}
    checks = verdict({**c.metrics, "molds": molds, "design_bend_radius": 0.5,
                      "boundary_panels": None}, limits, panel_size=2.0, units="m")
    by = {k["limit"]: k for k in checks}
    assert by["max_kink_deg"]["ok"] and by["max_kink_deg"]["advice"] is None
    assert by["mold_tolerance_mm"]["ok"] and by["mold_tolerance_mm"]["advice"] is None
    step = by["max_panel_step_mm"]
    assert not step["ok"] and step["advice"].startswith("a larger max_panel_step_mm, or a smaller")
    assert "the largest step is up to 9 times its limit" in step["advice"]
    assert all(k["advice"] is None for k in checks if k["ok"])


def test_a_search_refines_beside_a_net_on_the_design_before_one_off_it():
    """Without a feasible point, a search's best point is a net on the design, even when
    a net off the design misses its limits by less."""
    from fabplan.study.search import search_points
    from fabplan.study.spec import Search

    search = Search("lw", "linear-weingarten", "angle", 30.0, 60.0, budget=7)
    on = _point(search, 40.0, feasible=False, cost=30.0)      # 4 times its limit
    off = _point(search, 50.0, feasible=False, cost=1.0)      # 1.1 times
    off.metrics["status"] = "off-design"
    best = min(search_points(search, [on, off]), key=lambda p: p.rank_key)
    assert best.value == 40.0


def test_the_design_bend_radius_leaves_out_its_most_curved_twentieth():
    """A sharp part of under 5 % of the design's area does not set its bend radius; one of
    more does (a strip bent with radius 2, and with radius 0.5 along a part of it)."""
    import numpy as np

    from fabplan.design.mesh_surface import DesignSurface
    from fabplan.study.candidate_measure import bend_radius

    def strip(sharp_length, length=10.0, step=0.025):
        s = np.arange(0.0, length + step / 2, step)
        sharp = (s > 0.5 * (length - sharp_length)) & (s < 0.5 * (length + sharp_length))
        turn = np.concatenate([[0.0], np.cumsum(np.where(sharp, 2.0, 0.5)[:-1] * step)])
        x = np.concatenate([[0.0], np.cumsum(np.cos(turn[:-1]) * step)])
        z = np.concatenate([[0.0], np.cumsum(np.sin(turn[:-1]) * step)])
        n, w = len(s), 11
        X = np.column_stack([np.repeat(x, w), np.tile(np.linspace(0.0, 2.0, w), n),
                             np.repeat(z, w)])
        i = (np.arange(n - 1)[:, None] * w + np.arange(w - 1)[None, :]).reshape(-1, 1)
        quads = np.hstack([i, i + w, i + w + 1, i + 1])
        return DesignSurface(X, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))

    assert bend_radius(strip(0.2)) == pytest.approx(2.0, rel=0.05)      # 2 % of the area
    assert bend_radius(strip(1.0)) == pytest.approx(0.5, rel=0.05)      # 10 %


def test_the_panel_size_a_study_advises_is_laid_out_before_it_is_advised(judged, monkeypatch):
    """A study without a feasible candidate solves its general S-net at the largest panel
    size it advises, and says whether it converges there, so that its advice does not
    send a user to a size the next run refuses (a wavy facade at 2.5 m was told 0.52 m,
    where its 17 umbilics break every lattice; another's lattice held at 0.5 m and its
    solve left a gap of 105 panels at the design boundary)."""
    import re

    import fabplan.layout.surface_layout as surface_layout
    from fabplan.errors import BrokenLayoutError
    from fabplan.study.advised_size import check_advised_size

    study, result = judged
    said = []

    def advising(*sizes):
        """`result` with no feasible candidate, its nets advised the given sizes."""
        candidates = [dataclasses.replace(
            c, feasible=False, checks=[{**_failed("max_kink_deg", 10.0, 40.0),
                                        "advice": f"a smaller panel size, at most about {s:g} m",
                                        "advised_panel_size": s}])
            for c, s in zip([c for c in result.candidates if not c.failed][:len(sizes)], sizes,
                            strict=True)]
        return dataclasses.replace(result, candidates=candidates, recommended=None,
                                   recommendation="No candidate meets every limit.")

    advised = advising(0.5, 1.0)
    check_advised_size(advised, said.append)
    record = advised.advised_layout
    assert record["panel_size"] == 1.0 and record["lays_out"] is True   # the larger first
    assert record["panels"] >= 0.8 * result.design.area / 1.0**2
    assert said[0] == ("the panel size advised: a general S-net laid out and solved on the "
                       "design at 1 m")
    assert re.search(rf"At the largest panel size advised, 1 m, the general S-net on the design "
                     rf"converges \({record['panels']:,} panels, 100\.0 % of the design clad\)\.$",
                     advised.recommendation), advised.recommendation
    # beyond the study's panel limit it is not laid out, and says so
    advised = advising(1.0)
    check_advised_size(advised, said.append, max_panels=10)
    assert advised.advised_layout["lays_out"] is None
    assert re.search(r"The largest panel size advised, 1 m, was not tried here: about [\d,]+ "
                     r"panels, more than 10\.$", advised.recommendation), advised.recommendation
    # a lattice that does not hold together at that size: its reason, without the name
    def broken(design, size, **kw):
        raise BrokenLayoutError(f"{design.name}: the layout at panel size {size:g} does not "
                                "hold together: 17 umbilics")

    layout = surface_layout.layout_surface
    monkeypatch.setattr(surface_layout, "layout_surface", broken)
    advised = advising(1.0)
    check_advised_size(advised, said.append)
    assert advised.advised_layout["lays_out"] is False
    # and the sizes between it and the study's own (2 m) are tried, smallest first
    assert [b["panel_size"] for b in advised.advised_layout["between"]] == [1.2, 1.5]
    assert advised.recommendation.endswith(
        "The largest panel size advised, 1 m, does not lay out on this design, though: the "
        "layout at panel size 1 does not hold together: 17 umbilics. Nor does the general "
        "S-net converge at 1.2 or 1.5 m, the sizes tried between 1 m and the study's 2 m.")
    # a size between that gives a net is named
    monkeypatch.setattr(surface_layout, "layout_surface", lambda design, size, **kw: (
        broken(design, size) if size < 1.5 else layout(design, size, **kw)))
    advised = advising(1.0)
    check_advised_size(advised, said.append)
    record = advised.advised_layout
    assert [(b["panel_size"], b["lays_out"]) for b in record["between"]] == [(1.2, False),
                                                                            (1.5, True)]
    assert advised.recommendation.endswith(
        f"At 1.5 m, between 1 m and the study's 2 m, the general S-net converges "
        f"({record['between'][1]['panels']:,} panels): the smallest size tried that gives a net, "
        "larger than the limits ask for.")
    # whatever goes wrong in the check, the study's results are kept
    def failing(design, size, **kw):
        raise TypeError("no such thing")

    monkeypatch.setattr(surface_layout, "layout_surface", failing)
    advised = advising(1.0)
    check_advised_size(advised, said.append)
    assert advised.advised_layout["lays_out"] is None
    assert advised.recommendation.endswith("Whether the largest panel size advised, 1 m, gives a "
                                           "net could not be checked (TypeError: no such thing).")
    # a feasible study, or one that advises no size, is left as it is
    plain = dataclasses.replace(result, recommended=None, recommendation="x", candidates=[
        dataclasses.replace(c, checks=[_failed("max_molds", 3, 9)]) for c in result.candidates])
    check_advised_size(plain, said.append)
    assert plain.advised_layout is None and plain.recommendation == "x"


def test_a_relaxation_a_study_file_would_refuse_is_none_and_says_why():
    """A strips congruence tolerance relaxed past the range a cutting machine works to,
    or a kink past 180 deg, is no relaxation: the check has no relax_to (so the candidate
    is not said to be feasible with it) and its advice says why (a roof was told 11 mm,
    which the study file then refused after a whole run)."""
    from fabplan.study.checks import check, next_steps

    strips = check("congruent_strips", 0.1, 10.6, False, "x")
    assert strips["relax_to"] is None and relaxation_text([strips]) == ""
    assert next_steps([strips]) == [
        "no relaxation: a congruence tolerance of the strips of 10.6 mm would be needed, and "
        "the limit must be at most 10 mm (range [0.001, 10])"]
    kink = check("max_kink_deg", 10.0, 179.5, False, "x", advice="a smaller panel size")
    assert kink["relax_to"] is None
    assert kink["advice"].endswith("must lie between 0 and 180 degrees; or a smaller panel size")
    # without advice of its own, the general step is kept
    assert check("max_kink_deg", 10.0, 179.5, False, "x")["advice"].endswith("; or a smaller "
                                                                          "panel size")
    # within range, as before
    assert check("congruent_strips", 0.1, 8.4, False, "x")["relax_to"] == 8.4
    assert check("mold_tolerance_mm", 1.0, 40.2, False, "x")["relax_to"] == 41.0


def test_a_relaxation_of_the_mold_tolerance_with_other_limits_says_the_molds_change():
    """Relaxing the mold tolerance re-plans the molds, so the other figures a relaxation
    names for the same candidate move with them (a new user's facade, every limit set as
    told, missed the deviation named by 19 mm): the sentence says so; alone, or without
    it, it does not."""
    from fabplan.study.checks import feasible_with

    gap, dev = _failed("mold_tolerance_mm", 1.0, 40.2), _failed("max_deviation_mm", 30.0, 185.3)
    assert "planned anew" in feasible_with([gap, dev])
    assert "planned anew" not in feasible_with([gap])
    assert "planned anew" not in feasible_with([dev])


def test_a_candidate_whose_solve_gave_no_net_is_bound_by_that_not_by_a_limit_it_passes():
    """A crumpled net's binding limit was a mold check it passed (39.7 of 41 mm): a failed
    check without a margin binds first."""
    from fabplan.study.checks import check

    solve = {**_failed("max_sphere_residual", 1e-6, 2.8e-15), "margin": None}
    gap = check("mold_tolerance_mm", 41.0, 39.7, True, "x")
    assert binding_check([gap, solve])["limit"] == "max_sphere_residual"
    assert binding_check([gap])["limit"] == "mold_tolerance_mm"


@pytest.mark.slow
def test_a_study_run_records_the_check_of_its_advised_size():
    """`run_study` checks the size an infeasible study advises, and study.json and the
    recommendation carry it: here a kink limit of 0.2 deg asks for panels so small that
    there are more than are solved to check it."""
    from fabplan.study.records import study_record

    text = STUDY.replace("max_molds = 3", "max_molds = 3\nmax_kink_deg = 0.2")
    result = run_study(parse_study(text))
    assert result.recommended is None
    record = study_record(result)["advised_layout"]
    assert record is not None and record["lays_out"] is None and record["between"] == []
    assert record["text"] in result.recommendation
    assert record["text"].startswith(f"The largest panel size advised, {record['panel_size']:g} m, "
                                     "was not tried here: about")


def test_a_relaxation_sets_each_failed_limit_to_what_passes_it():
    """The limits a relaxation names are the study's with each failed check's limit set
    to its `relax_to` (the strips' congruence check relaxes their tolerance); a failed
    check without one (a solve that gave no net) makes no relaxation."""
    from fabplan.study.definition import Limits
    from fabplan.study.relaxation_check import relaxed_limits

    now = Limits(max_deviation_mm=30.0, mold_tolerance_mm=1.0, max_molds=30)
    ok = {**_failed("max_kink_deg", 8.0, 4.0), "ok": True}
    relaxed = relaxed_limits(now, [_failed("max_deviation_mm", 30.0, 185.3),
                                   _failed("congruent_strips", 0.1, 8.4), ok])
    assert relaxed == dataclasses.replace(now, max_deviation_mm=190.0,
                                          congruence_tolerance_mm=8.4)
    assert relaxed_limits(now, [ok]) is None
    assert relaxed_limits(now, [_failed("max_deviation_mm", 30.0, 185.3),
                                {**_failed("max_sphere_residual", 1e-6, 0.3)}]) is None


def _nearest_told(result, *checks):
    """`result` without a feasible candidate, its first measured one failing `checks`
    (the nearest) and the others further off, as `judge_study` recommends it."""
    from fabplan.study.ranking import _nearest_text

    measured = [c for c in result.candidates if not c.failed]
    far = [_failed("max_deviation_mm", 30.0, 9000.0), _failed("max_molds", 3, 900)]
    candidates = [dataclasses.replace(c, feasible=False, checks=list(checks) if k == 0 else far,
                                      reasons=[x["text"] for x in (checks if k == 0 else far)])
                  for k, c in enumerate(measured)]
    return dataclasses.replace(result, candidates=candidates, recommended=None,
                               recommendation=_nearest_text(candidates))


def test_a_relaxation_that_changes_the_run_is_run_before_it_is_told(judged, monkeypatch):
    """The relaxation of a study's nearest candidate that changes its molds or its held
    deviation is run again before it is told, and relaxed once more by what that run
    measured (a new user who set every limit as told found a boundary panel 209 mm off,
    against the 190 mm named); one the verdict alone judges is not run."""
    import fabplan.study.relaxation_check as relaxation
    from fabplan.study.checks import check, feasible_with

    _, result = judged
    runs = []

    def run_under(study, result, nearest, say, *kept):
        """The candidate as a run under `study`'s limits measures it: its boundary panels
        209.2 mm off the design at a mold tolerance of 41 mm."""
        runs.append(study.limits)
        dev = 209.2 if study.limits.mold_tolerance_mm > 10 else 185.3
        return dataclasses.replace(nearest, metrics={**nearest.metrics, "dev": dev})

    def judge(study, design, made):
        """`made` judged under `study`'s limits, as `judge_study` judges it."""
        limits, dev = study.limits, made[0].metrics["dev"]
        checks = [check("max_deviation_mm", limits.max_deviation_mm, dev,
                        dev <= limits.max_deviation_mm, f"boundary panels {dev} mm off"),
                  check("mold_tolerance_mm", limits.mold_tolerance_mm, 40.2,
                        40.2 <= limits.mold_tolerance_mm, "gaps of 40.2 mm")]
        return dataclasses.replace(result, candidates=[dataclasses.replace(
            made[0], checks=checks, feasible=all(c["ok"] for c in checks))])

    monkeypatch.setattr(relaxation, "judge_study", judge)
    monkeypatch.setattr(relaxation, "_run_under", run_under)
    told = [_failed("max_deviation_mm", 30.0, 185.3), _failed("mold_tolerance_mm", 2.0, 40.2)]
    study = _nearest_told(result, *told)
    name = next(c.name for c in result.candidates if not c.failed)
    relaxation.check_relaxation(study, lambda s: None)
    record = study.relaxation_check
    assert [r["limits"] for r in record["rounds"]] == [
        {"max_deviation_mm": 190.0, "mold_tolerance_mm": 41.0},
        {"max_deviation_mm": 210.0, "mold_tolerance_mm": 41.0}]
    assert [r["feasible"] for r in record["rounds"]] == [False, True]
    # the nearest here glides on the design: a deviation relaxed further changes nothing
    # its run is made with, and the second round judges the first run again
    assert [r["ran"] for r in record["rounds"]] == [True, False] and len(runs) == 1
    assert record["rounds"][0]["failed"] == {"max_deviation_mm": 209.2}
    assert record["feasible"] is True
    assert record["limits"] == {"max_deviation_mm": 210.0, "mold_tolerance_mm": 41.0}
    # said right after the relaxation it checks
    assert f"{feasible_with(told).strip()} {record['text']}" in study.recommendation
    assert record["text"] == (
        f"Run again under those limits (its net solved and its molds planned anew), {name} "
        f"still fails: boundary panels 209.2 mm off. It meets every limit with a largest "
        "deviation from the design of 210 mm (now 30 mm) and a largest gap between a panel and "
        "its mold of 41 mm (now 2 mm), the other limits as they are.")
    # a relaxation of the molds counted only: the verdict alone judges it, nothing is run
    runs.clear()
    counted = _nearest_told(result, _failed("max_molds", 3, 9))
    relaxation.check_relaxation(counted, lambda s: None)
    assert runs == [] and counted.relaxation_check is None
    # a second round that relaxes only limits the verdict judges: judged on the same run
    def counting(study, design, made):
        judged = judge(study, design, made).candidates[0]
        molds = check("max_molds", study.limits.max_molds, 9, 9 <= study.limits.max_molds,
                      "9 molds")
        checks = [*judged.checks, molds]
        return dataclasses.replace(result, candidates=[dataclasses.replace(
            judged, checks=checks, feasible=all(c["ok"] for c in checks))])

    monkeypatch.setattr(relaxation, "judge_study", counting)
    runs.clear()
    gaps = _nearest_told(result, _failed("mold_tolerance_mm", 2.0, 40.2))
    relaxation.check_relaxation(gaps, lambda s: None)
    record = gaps.relaxation_check
    assert [(r["ran"], r["feasible"]) for r in record["rounds"]] == [(True, False), (False, True)]
    assert len(runs) == 1 and record["limits"] == {"max_deviation_mm": 210.0,
                                                   "mold_tolerance_mm": 41.0, "max_molds": 9}
    assert record["text"].endswith("It meets every limit with a largest deviation from the "
                                   "design of 210 mm (now 30 mm) and a largest gap between a "
                                   "panel and its mold of 41 mm (now 2 mm) and at most 9 molds "
                                   "(now 3), the other limits as they are.")
    # a run that fails as it did, past any relaxation: said, and none is named
    monkeypatch.setattr(relaxation, "judge_study", lambda study, design, made: dataclasses.replace(
        result, candidates=[dataclasses.replace(made[0], feasible=False, checks=[
            {**_failed("max_sphere_residual", 1e-6, 0.3), "text": "crumpled"}])]))
    stuck = _nearest_told(result, *told)
    relaxation.check_relaxation(stuck, lambda s: None)
    assert stuck.relaxation_check["feasible"] is False
    assert stuck.relaxation_check["limits"] is None
    assert stuck.relaxation_check["text"].endswith("still fails: crumpled. No limit relaxed "
                                                   "further would do.")
    # whatever goes wrong in the run, the study's results are kept
    def failing(*args):
        raise TypeError("no such thing")

    monkeypatch.setattr(relaxation, "_run_under", failing)
    broken = _nearest_told(result, *told)
    relaxation.check_relaxation(broken, lambda s: None)
    assert broken.relaxation_check["feasible"] is None
    assert broken.relaxation_check["text"] == (
        f"Whether {name} is feasible under those limits could not be checked (TypeError: no "
        "such thing).")
    # in a second round, after what the first found: its molds at 41 mm leave gaps of 45
    def wider(study, design, made):
        gap = 45.0 if study.limits.mold_tolerance_mm == 41.0 else 40.2
        limit = study.limits.mold_tolerance_mm
        checks = [check("mold_tolerance_mm", limit, gap, gap <= limit, f"gaps of {gap} mm")]
        return dataclasses.replace(result, candidates=[dataclasses.replace(
            made[0], checks=checks, feasible=all(c["ok"] for c in checks))])

    monkeypatch.setattr(relaxation, "judge_study", wider)
    monkeypatch.setattr(relaxation, "_run_under", lambda study, result, nearest, say, *kept: (
        run_under(study, result, nearest, say) if not runs else failing()))
    runs.clear()
    second = _nearest_told(result, _failed("mold_tolerance_mm", 2.0, 40.2))
    relaxation.check_relaxation(second, lambda s: None)
    record = second.relaxation_check
    assert record["feasible"] is None and len(record["rounds"]) == 1
    assert record["text"].startswith(f"Run again under those limits (its net solved and its "
                                     f"molds planned anew), {name} still fails: gaps of 45.0")
    assert record["text"].endswith(f"Whether {name} is feasible under further relaxed limits "
                                   "could not be checked (TypeError: no such thing).")


@pytest.mark.slow
def test_the_limits_a_study_names_for_its_nearest_candidate_make_it_feasible():
    """What an infeasible study says its nearest candidate would be feasible with holds
    when a user sets the study's limits so and runs it again: a mold tolerance of 0.05 mm
    on the hypar relaxes the tolerance, the steps and the molds counted, and the molds
    planned at the relaxed tolerance are fewer than those counted at 0.05 mm, so the
    molds counted are set back to what the new molds need."""
    from fabplan.study.records import study_record

    text = STUDY.replace("mold_tolerance_mm = 2", "mold_tolerance_mm = 0.05")
    result = run_study(parse_study(text))
    record = study_record(result)["relaxation_check"]
    assert result.recommended is None and record is not None and record["feasible"] is True
    nearest = next(c for c in result.candidates if c.name == record["candidate"])
    told = {c["limit"]: c["relax_to"] for c in nearest.checks if not c["ok"]}
    assert record["rounds"][0]["limits"] == told and "mold_tolerance_mm" in told
    assert record["text"] in result.recommendation
    # the user's run: the study's limits set as told, the nearest candidate alone
    limits = "\n".join(f"{k} = {v!r}" for k, v in record["limits"].items())
    again = text.split("[limits]")[0] + f"[limits]\nmax_deviation_mm = 30\n{limits}\n"
    if nearest.candidate.net != "snet":
        again += f"[[candidates]]\nnet = \"{nearest.candidate.net}\"\nangle = 80\n"
    rerun = run_study(parse_study(again))
    assert rerun.recommended is not None, rerun.recommendation
    assert rerun.relaxation_check is None
    ran = next(c for c in rerun.candidates if c.name == record["candidate"])
    assert ran.feasible
    assert ran.metrics["molds"]["count"] <= record["limits"].get("max_molds", 3)


def test_the_report_says_where_a_net_off_the_design_was_solved(judged):
    """A net that leaves the design is solved on the design continued past its edges, or
    on the design alone, and the candidate's page says which and why: the same linear
    Weingarten candidate ended 14.8 mm off a saddle in one study and 43.9 mm in the same
    study with strips added, and nothing said that a lamella study solves it on the design
    alone."""
    from fabplan.study.definition import StripOptions
    from fabplan.study.tables import candidate_facts

    study, result = judged
    weingarten = next(c for c in result.candidates if c.candidate.net == "linear-weingarten")
    isogonal = next(c for c in result.candidates if c.candidate.net == "isogonal")

    def solve_row(c, r=result):
        return dict(candidate_facts(c, r)[1])["solve"]

    assert weingarten.metrics["continued"] is True
    assert solve_row(weingarten).endswith("; solved on the design continued past its edges")
    assert "solved on" not in solve_row(isogonal)              # on the design itself
    lamellas = dataclasses.replace(result, study=dataclasses.replace(
        study, strips=StripOptions(height_mm=80, thickness_mm=4, nets="all")))
    alone = dataclasses.replace(weingarten, metrics={**weingarten.metrics, "continued": False})
    assert solve_row(alone, lamellas).endswith(
        "; solved on the design alone (a lamella study: its strips end on the net's own tips)")


@pytest.mark.slow
def test_a_resumed_study_takes_the_runs_of_its_relaxation_from_its_cache(tmp_path, capsys):
    """`--resume` keeps the nearest candidate's runs under its relaxed limits beside the
    candidates, and a resumed study takes them from there: the same check, not solved
    again."""
    import json

    from fabplan.cli import main

    study = tmp_path / "s.toml"
    study.write_text(STUDY.replace("mold_tolerance_mm = 2", "mold_tolerance_mm = 0.05"))
    out = tmp_path / "out"
    argv = ["study", str(study), "-o", str(out), "--resume", "--workers", "1", "--no-3d"]
    assert main(argv) == 3
    first = json.loads((out / "study.json").read_text())["relaxation_check"]
    assert first is not None and first["rounds"]
    capsys.readouterr()
    assert main(argv) == 3
    said = capsys.readouterr()
    assert "under those limits: taken from the cache" in said.out + said.err
    again = json.loads((out / "study.json").read_text())["relaxation_check"]
    assert again == first
