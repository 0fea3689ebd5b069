"""``rcac bench core``: the recursive controller against Pinocchio, the Slotine-Li baseline
and itself.

Chains of n = 7, 14, ..., 224 are the CSS arm repeated. Each figure is the
median over blocks of the mean time per call (µs), measured in one run on this
machine; the ratios are what the targets are about. The operation count is
exact (:mod:`rcac_ros.tools.bench.opcount`).

Besides the paper's law (channels ``[1]``) the table times the recursive law with the
channels ``[1, "power"]`` and ``"all"`` (implicit and explicit update), with the
least-squares gain (channels ``[1]``), with the joint terms (``joint_friction=True``,
doc/design.md §7) and with the natural geometry (doc/design.md §8), against n.
"""

import json
import time

import numpy as np

from rcac_ros.core import (RecursiveCompositeController, Simulator, SlotineLiCompositeController,
                           css_arm)
from rcac_ros.core.pseudo_inertia import default_start

SIZES = (7, 14, 28, 56, 112, 224)

#: column -> options of the recursive law timed besides the paper's default
VARIANTS = {
    "power_us": dict(channels=[1, "power"]),
    "all_us": dict(channels="all"),
    "all_explicit_us": dict(channels="all", update="explicit"),
    "least_squares_us": dict(adaptation="least_squares", forgetting=1.0),
    "natural_us": dict(geometry="natural"),      # doc/design.md §8
    "friction_us": dict(joint_friction=True),
}


def start_for(model, kwargs):
    """The variant's initial estimates: the model's own, or (natural geometry, which needs a
    body per link) its default start."""
    if kwargs.get("geometry") == "natural":
        return default_start(model.theta())
    return model.theta()


def _timed(fn, reps, clock=time.perf_counter):
    """Seconds (of ``clock``) for ``reps`` calls of ``fn()``."""
    t0 = clock()
    for _ in range(reps):
        fn()
    return clock() - t0


def _reps(budget_s, blocks, *fns):
    """Calls per block so that ``blocks`` blocks of every ``fn`` take about ``budget_s``.

    Each ``fn`` is called once first (compilation, caches), then timed once.
    """
    for fn in fns:
        fn()
    once = max(sum(_timed(fn, 1) for fn in fns), 1e-7)
    return max(1, int(budget_s / blocks / once))


def median_us(fn, budget_s=0.3, blocks=7):
    """Median over ``blocks`` of the mean µs per call of ``fn()``, about ``budget_s`` in all."""
    reps = _reps(budget_s, blocks, fn)
    return float(np.median([_timed(fn, reps) / reps * 1e6 for _ in range(blocks)]))


def interleaved_ratio(fa, fb, budget_s=1.0, blocks=15, clock=time.perf_counter):
    """Median over blocks of ``time(fa) / time(fb)``, the two timed alternately.

    On a shared machine the load changes between cells; timed side by side, block by
    block, the ratio is far steadier than the ratio of two medians. ``clock``:
    ``time.process_time`` leaves out the time the process waits for a core.
    """
    reps = _reps(budget_s, blocks, fa, fb)
    return float(np.median([_timed(fa, reps, clock) / _timed(fb, reps, clock)
                            for _ in range(blocks)]))


def recorded_inputs(model, seconds=2.0, offset=0.1):
    """The inputs ``(q, qd, q_d, qd_d, qdd_d)`` of every period of a closed loop: the
    Euclidean paper law from the natural geometry's default start
    (:func:`~rcac_ros.core.pseudo_inertia.default_start`) on the built-in simulator, tracking
    the paper's trajectory from ``offset`` rad off it (the paper's start, repeated along the
    chain)."""
    from rcac_ros.core import PaperTrajectory
    from rcac_ros.core.model import PAPER_Q0
    q0 = np.resize(np.array(PAPER_Q0), model.n)
    ctrl = RecursiveCompositeController(model, theta_hat0=default_start(model.theta()))
    traj = PaperTrajectory(q0)
    sim = Simulator(model, dt=ctrl.h, q0=q0 + offset)
    out = []
    for k in range(int(round(seconds / ctrl.h))):
        desired = tuple(np.ascontiguousarray(a) for a in traj(k * ctrl.h))
        args = (sim.q.copy(), sim.qd.copy()) + desired
        out.append(args)
        sim.step(ctrl.step(*args))
    return out


class Replay:
    """``ctrl.step`` along recorded inputs, one period per call, from the start again after
    the last one (:func:`recorded_inputs`)."""

    def __init__(self, ctrl, inputs):
        self.ctrl, self.inputs, self.k = ctrl, inputs, 0

    def __call__(self):
        self.ctrl.step(*self.inputs[self.k])
        self.k = (self.k + 1) % len(self.inputs)


def natural_baselines(model):
    """The natural law with the log-det metric (doc/design.md §8), two Euclidean baselines
    and the natural law with its default metric (the barrier), all from the natural default
    start: ``(log_det, paper, general, barrier)``, ``paper`` the paper's law as a user runs
    it (its fused kernel, :func:`~rcac_ros.core.composite_fused.paper_step`) and ``general``
    the same law on the general kernel's path by a projection onto infinite bounds (the same
    estimates, bit for bit, plus 13 n clips)."""
    start = default_start(model.theta())
    nat = RecursiveCompositeController(model, theta_hat0=start, geometry="natural",
                                       natural_metric="log_det")
    paper = RecursiveCompositeController(model, theta_hat0=start)
    inf = np.full((model.n, 13), np.inf)
    general = RecursiveCompositeController(model, theta_hat0=start, theta_bounds=(-inf, inf))
    barrier = RecursiveCompositeController(model, theta_hat0=start, geometry="natural")
    return nat, paper, general, barrier


def natural_cost(sizes=(7, 14, 28), runs=3, budget_s=1.0):
    """The natural geometry's cost goal (doc/design.md §8), ``runs`` times back to back,
    medians of CPU-time ratios (``time.process_time``, :func:`interleaved_ratio`): per n,
    along a recorded closed loop (:func:`recorded_inputs`, the same inputs replayed by
    every law), the natural law over the Euclidean paper law (the goal's ratio) and over
    the same law on the general kernel's path (:func:`natural_baselines`), the barrier
    metric over the paper law, and the µs of a natural and a barrier step; at n = 7 the
    worst case: one random state repeated, which drives the estimates onto the
    retraction's floor (every step halved 30 times)."""
    clock = time.process_time
    loops = {}
    for n in sizes:
        model = css_arm().repeated(n // 7)
        inputs = recorded_inputs(model)
        loops[n] = [Replay(c, inputs) for c in natural_baselines(model)]
    rng = np.random.default_rng(0)
    args = tuple(rng.normal(size=(5, 7)) * 0.1)
    nat, paper, general, _ = natural_baselines(css_arm())
    figures = {}

    def add(key, value):
        figures.setdefault(key, []).append(value)
    for _ in range(runs):
        for n, (fn, fp, fg, fb) in loops.items():
            add(f"closed_loop_natural_over_paper_n{n}",
                interleaved_ratio(fn, fp, budget_s, clock=clock))
            add(f"closed_loop_natural_over_general_n{n}",
                interleaved_ratio(fn, fg, budget_s, clock=clock))
            add(f"closed_loop_barrier_over_paper_n{n}",
                interleaved_ratio(fb, fp, budget_s, clock=clock))
            for name, f in (("natural", fn), ("barrier", fb)):
                reps = _reps(budget_s / 4, 1, f)
                add(f"closed_loop_{name}_us_n{n}", _timed(f, reps, clock) / reps * 1e6)
        for key, base in (("paper", paper), ("general", general)):
            add(f"worst_case_natural_over_{key}_n7", interleaved_ratio(
                lambda: nat.step(*args), lambda: base.step(*args), budget_s, clock=clock))
    return {k: float(np.median(v)) for k, v in figures.items()}


def goal_ratios(budget_s=1.0):
    """The cost goals of doc/results.md ("Speed of one step"),
    each measured side by side (:func:`interleaved_ratio`)."""
    rng = np.random.default_rng(0)
    out = {}
    for n in (7, 56):
        model = css_arm().repeated(n // 7)
        args = tuple(rng.normal(size=(5, n)) * 0.1)
        paper = RecursiveCompositeController(model, theta_hat0=model.theta())
        every = RecursiveCompositeController(model, theta_hat0=model.theta(), channels="all")
        if n == 7:
            rnea = _pin_rnea(model)
            if rnea is not None:
                out["paper_over_pin_rnea_n7"] = interleaved_ratio(
                    lambda: paper.step(*args), lambda: rnea(args[0], args[1], args[4]), budget_s)
            out["all_over_paper_n7"] = interleaved_ratio(lambda: every.step(*args),
                                                         lambda: paper.step(*args), budget_s)
            fall = RecursiveCompositeController(model, theta_hat0=model.theta(), channels="all",
                                                joint_friction=True)
            out["friction_all_over_all_n7"] = interleaved_ratio(
                lambda: fall.step(*args), lambda: every.step(*args), budget_s)
            for key, kwargs in VARIANTS.items():
                if key != "all_us":
                    c = RecursiveCompositeController(model, theta_hat0=start_for(model, kwargs),
                                                     **kwargs)
                    out[f"{key[:-3]}_over_paper_n7"] = interleaved_ratio(
                        lambda: c.step(*args), lambda: paper.step(*args), budget_s)
            # the natural geometry against the Euclidean paper law from the same start, along
            # a recorded closed loop (the goal's figure) and at one random state repeated,
            # which drives the estimates onto the retraction's floor (its worst case)
            nat, paper_b, _, barrier = natural_baselines(model)
            loop = recorded_inputs(model)
            out["barrier_over_paper_closed_loop_n7"] = interleaved_ratio(
                Replay(barrier, loop), Replay(paper_b, loop), budget_s)
            out["log_det_over_paper_closed_loop_n7"] = interleaved_ratio(
                Replay(nat, loop), Replay(paper_b, loop), budget_s)
            out["log_det_over_paper_worst_case_n7"] = interleaved_ratio(
                lambda: nat.step(*args), lambda: paper_b.step(*args), budget_s)
        else:
            sl = SlotineLiCompositeController(model, theta_hat0=model.theta())
            out["all_over_slotine_li_n56"] = interleaved_ratio(
                lambda: every.step(*args), lambda: sl.step(*args), budget_s, blocks=7)
            expl = RecursiveCompositeController(model, theta_hat0=model.theta(),
                                                channels="all", update="explicit")
            out["all_explicit_over_slotine_li_n56"] = interleaved_ratio(
                lambda: expl.step(*args), lambda: sl.step(*args), budget_s, blocks=7)
            fric = RecursiveCompositeController(model, theta_hat0=model.theta(),
                                                joint_friction=True)
            out["friction_over_paper_n56"] = interleaved_ratio(
                lambda: fric.step(*args), lambda: paper.step(*args), budget_s)
    return out


def _pin_rnea(model):
    try:
        import pinocchio as pin
    except ImportError:
        return None
    pm = pin.Model()
    parent = 0
    for i in range(model.n):
        parent = pm.addJoint(parent, pin.JointModelRZ(),
                             pin.SE3(np.array(model.R_fix[i]), np.array(model.p[i])), f"j{i}")
        pm.appendBodyToJoint(parent, pin.Inertia(float(model.mass[i]), np.array(model.com[i]),
                                                 np.array(model.inertia[i])), pin.SE3.Identity())
    pm.gravity.linear = np.array(model.gravity)
    data = pm.createData()
    return lambda q, qd, qdd: pin.rnea(pm, data, q, qd, qdd)


def bench_model(model, label, baseline=True, budget_s=0.3):
    """One row: µs per controller step, pin.rnea, Slotine-Li step and simulator step."""
    rng = np.random.default_rng(0)
    q, qd, q_d, qd_d, qdd_d = rng.normal(size=(5, model.n)) * 0.1
    ctrl = RecursiveCompositeController(model, theta_hat0=model.theta())
    row = {"model": label, "n": model.n,
           "controller_us": median_us(lambda: ctrl.step(q, qd, q_d, qd_d, qdd_d), budget_s)}
    for key, kwargs in VARIANTS.items():
        c = RecursiveCompositeController(model, theta_hat0=start_for(model, kwargs), **kwargs)
        row[key] = median_us(lambda: c.step(q, qd, q_d, qd_d, qdd_d), budget_s,
                             blocks=3 if model.n > 100 else 7)
    rnea = _pin_rnea(model)
    row["pin_rnea_us"] = None if rnea is None else median_us(lambda: rnea(q, qd, qdd_d), budget_s)
    if baseline:
        sl = SlotineLiCompositeController(model, theta_hat0=model.theta())
        row["slotine_li_us"] = median_us(lambda: sl.step(q, qd, q_d, qd_d, qdd_d), budget_s,
                                         blocks=3 if model.n > 100 else 7)
    else:
        row["slotine_li_us"] = None
    sim = Simulator(model, q0=q)
    tau = np.zeros(model.n)
    row["simulator_us"] = median_us(lambda: sim.step(tau), budget_s)
    return row


def urdf_models():
    """The panda (to panda_link8) and the ur5 from example-robot-data, if both are installed."""
    from rcac_ros.core.urdf import model_from_urdf
    from rcac_ros.tools.runs.robots import example_robot_urdf
    out = []
    for label, rel, tip in (("panda", "panda_description/urdf/panda.urdf", "panda_link8"),
                            ("ur5", "ur_description/urdf/ur5_robot.urdf", None)):
        path = example_robot_urdf(rel)
        if path is None:
            print(f"(example-robot-data not installed: no {label} row)")
            continue
        out.append((label, model_from_urdf(path, tip_link=tip)))
    return out


def run_bench(sizes=SIZES, budget_s=0.3, with_urdf=True, ops=True):
    """All rows, the ratios and the operation counts, as a dict."""
    rows = []
    base = css_arm()
    for n in sizes:
        rows.append(bench_model(base.repeated(n // 7), f"css x{n // 7}", budget_s=budget_s))
        print(_format_row(rows[-1]), flush=True)
    if with_urdf:
        for label, model in urdf_models():
            rows.append(bench_model(model, label, budget_s=budget_s))
            print(_format_row(rows[-1]), flush=True)
    by_n = {r["n"]: r for r in rows if r["model"].startswith("css")}
    ratios = {}
    if 7 in by_n and by_n[7]["pin_rnea_us"]:
        ratios["controller_n7_over_pin_rnea_n7"] = (by_n[7]["controller_us"]
                                                    / by_n[7]["pin_rnea_us"])
    if 224 in by_n and 28 in by_n:
        ratios["controller_n224_over_n28"] = by_n[224]["controller_us"] / by_n[28]["controller_us"]
        ratios["friction_n224_over_n28"] = by_n[224]["friction_us"] / by_n[28]["friction_us"]
    if 56 in by_n and by_n[56]["slotine_li_us"]:
        ratios["slotine_li_over_controller_n56"] = (by_n[56]["slotine_li_us"]
                                                    / by_n[56]["controller_us"])
        ratios["all_over_slotine_li_n56"] = by_n[56]["all_us"] / by_n[56]["slotine_li_us"]
        ratios["all_explicit_over_slotine_li_n56"] = (by_n[56]["all_explicit_us"]
                                                      / by_n[56]["slotine_li_us"])
    if 7 in by_n:
        for key in VARIANTS:
            ratios[f"{key[:-3]}_over_paper_n7"] = by_n[7][key] / by_n[7]["controller_us"]
    for r in rows:
        if r["model"] in ("panda", "ur5") and r["pin_rnea_us"]:
            ratio = r["controller_us"] / r["pin_rnea_us"]
            ratios[f"controller_over_pin_rnea_{r['model']}"] = ratio
    result = {"rows": rows, "ratios": ratios, "goals": goal_ratios()}
    if ops:
        from rcac_ros.tools.bench.opcount import count_step
        c7, c14 = count_step("rcac", 7), count_step("rcac", 14)
        result["operations"] = {
            "rcac_n7": c7, "rcac_n14": c14,
            "rcac_per_link_mul": (c14["mul"] + c14["div"] - c7["mul"] - c7["div"]) / 7,
            "rcac_per_link_add": (c14["add"] - c7["add"]) / 7,
            "slotine_li_n7": count_step("slotine_li", 7),
            "paper_per_link": {"mul": 606, "add": 501},
        }
        # the all-channel law: a n^2 + b n + c multiplications, fitted on n = 7, 14, 21
        counts = {k: count_step("rcac_all", k) for k in (7, 14, 21)}
        for kind in ("rcac_all_explicit", "rcac_power", "rcac_least_squares"):
            result["operations"][f"{kind}_n7"] = count_step(kind, 7)
        ns = np.array([7.0, 14.0, 21.0])
        mul = np.array([counts[k]["mul"] + counts[k]["div"] for k in (7, 14, 21)])
        a, b, c = np.linalg.solve(np.vander(ns, 3), mul)
        result["operations"]["rcac_all"] = {str(k): v for k, v in counts.items()}
        result["operations"]["rcac_all_mul_fit"] = {"n2": a, "n": b, "1": c,
                                                    "wang_n2": 7730}
    return result


def _format_row(r):
    def f(v):
        return f"{v:12.2f}" if v is not None else f"{'-':>12s}"
    return (f"{r['model']:>10s} {r['n']:5d} {f(r['controller_us'])} {f(r['pin_rnea_us'])} "
            f"{f(r['slotine_li_us'])} {f(r['simulator_us'])}"
            + "".join(f"     {f(r[k])}" for k in VARIANTS))


def main(budget=0.3, json_path=None, natural=False):
    """``rcac bench core``: print the table, the ratios and the operation counts
    (``natural``: only the natural geometry's cost, :func:`natural_cost`)."""
    if natural:
        figures = natural_cost()
        print("natural geometry over the Euclidean law (target <= 1.3 at n = 7 over the paper "
              "law, linear in n), CPU time, 3 runs, medians:")
        for k, v in figures.items():
            print(f"  {k:40s} {v:8.3f}")
        return 0
    try:
        import pinocchio  # noqa: F401
    except ImportError:
        print("pinocchio (pip package 'pin') is not installed: the pin.rnea column is skipped")
    print(f"{'model':>10s} {'n':>5s} {'step us':>12s} {'pin.rnea us':>12s} "
          f"{'SlotineLi us':>12s} {'sim step us':>12s}"
          + "".join(f" {k[:-3] + ' us':>16s}" for k in VARIANTS))
    result = run_bench(budget_s=budget)
    print("\nratios (targets: n7/pin <= 3, n224/n28 <= 10, SlotineLi/step at n56 >= 20,\n"
          "        all/paper at n7 <= 2, all/SlotineLi at n56 <= 0.1, friction n224/n28 <= 10):")
    for k, v in result["ratios"].items():
        print(f"  {k:40s} {v:8.2f}")
    print("\ncost goals, each timed side by side (targets: paper/pin.rnea <= 3, all/paper <= 2, "
          "friction/paper <= 1.3, natural/paper <= 1.3 along a closed loop at n = 7; "
          "all/SlotineLi <= 0.1 at n = 56; friction linear "
          "in n: n224/n28 <= 10):")
    for k, v in result["goals"].items():
        print(f"  {k:40s} {v:8.3f}")
    ops = result.get("operations")
    if ops:
        print(f"\noperations per step (counted): n=7 {ops['rcac_n7']}; per link "
              f"{ops['rcac_per_link_mul']:.0f} mul + {ops['rcac_per_link_add']:.0f} add "
              f"(paper: 606 mul + 501 add); Slotine-Li n=7 {ops['slotine_li_n7']}")
        fit = ops["rcac_all_mul_fit"]
        print(f"channels='all': {fit['n2']:.0f} n^2 + {fit['n']:.0f} n + {fit['1']:.0f} "
              f"multiplications (Wang's O(n^2) law, as the paper cites: 7730 n^2); "
              f"n=7 {ops['rcac_all']['7']}")
        for kind in ("rcac_all_explicit", "rcac_power", "rcac_least_squares"):
            print(f"{kind} n=7: {ops[kind + '_n7']}")
    if json_path:
        with open(json_path, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
        print(f"wrote {json_path}")
    return 0
