"""Time ``make demo`` and ``make test`` as a new user runs them, for doc/results.md.

``python -m rcac_ros.tools.results.timings --clean`` (``make readme-timings``) clones the
committed HEAD into a temporary folder and runs both targets there, as a new user would on a
fresh machine (the venv created and installed, numba's one-time compile, the demo, the whole
test suite). Without ``--clean`` it runs them in this checkout, with its venv as it is. It
stores the figures measured (each target's wall time, the demo's own run time and the test
counts) as the source ``timings`` of doc/results.md (``doc/results/timings.json``) and
renders the page.
The output of both targets is printed as it comes (a long run shows progress).
"""

import argparse
import codecs
import datetime
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time

from rcac_ros.tools.results.blocks import TIMINGS_TEMPLATE as TEMPLATE

DEMO_WALL = re.compile(r"rcac demo: ([\d.]+) s simulated in ([\d.]+) s wall")
PYTEST_SUMMARY = re.compile(r"^=*\s*(\d+ passed[^=]*?) in [\d.]+s", re.MULTILINE)


def pytest_counts(output):
    """``'212 passed, 3 skipped'`` from pytest's last summary line (warnings left out); None
    if there is none."""
    found = PYTEST_SUMMARY.findall(output)
    if not found:
        return None
    parts = [p.strip() for p in found[-1].split(",")]
    return ", ".join(p for p in parts if p and not p.endswith(("warning", "warnings")))


def timed(command, cwd, env, poll=0.5):
    """Run ``command`` in ``cwd``, echoing its output every ``poll`` s; return (seconds,
    output, exit code)."""
    print(f"readme-timings: {' '.join(command)} (in {cwd})", flush=True)
    # through a file, not a pipe: a process the target leaves behind cannot hold the read open
    decode = codecs.getincrementaldecoder("utf-8")(errors="replace").decode
    with tempfile.TemporaryFile() as log:
        t0 = time.monotonic()
        proc = subprocess.Popen(command, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT)
        done, pos, text, shown = False, 0, "", 0
        while not done:
            done = proc.poll() is not None
            elapsed = time.monotonic() - t0
            # pread: the child shares the file's offset, so a seek and read here would move
            # where its next line lands
            while chunk := os.pread(log.fileno(), 1 << 20, pos):
                text += decode(chunk)
                pos += len(chunk)
            text += decode(b"", final=done)
            end = len(text) if done else text.rfind("\n") + 1
            for line in text[shown:end].splitlines():
                print(f"  [{elapsed:6.0f} s] {line}", flush=True)
            shown = max(shown, end)
            if not done:
                time.sleep(poll)
    return elapsed, text, proc.returncode


def measure(root, clean):
    """Run ``make demo`` then ``make test`` (in a clone of HEAD if ``clean``); their fields."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "ROS_DOMAIN_ID", "NUMBA_CACHE_DIR",
                        "RCAC_CACHE_DIR")}
    work = tempfile.mkdtemp(prefix="rcac_timings_") if clean else None
    if clean:   # the compiled kernels too start empty, as on a fresh machine
        env["RCAC_CACHE_DIR"] = os.path.join(work, "kernels")
    try:
        where = root
        if clean:
            where = os.path.join(work, "rcac_ros")
            subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", root, where],
                           check=True)
        out = os.path.join(work or root, "results")
        demo_s, demo_out, code = timed(["make", "demo", f"OUT={out}"], where, env)
        if code:
            raise SystemExit(f"readme-timings: make demo failed (exit {code})")
        test_s, test_out, code = timed(["make", "test"], where, env)
        if code:
            raise SystemExit(f"readme-timings: make test failed (exit {code}): "
                             "doc/results/timings.json is kept as it was")
    finally:
        if work:
            shutil.rmtree(work, ignore_errors=True)
    wall = DEMO_WALL.search(demo_out)
    parts = ["install, the one-time compile" if clean else "the venv as it was"]
    if wall:
        parts.append(f"{float(wall.group(1)):g} s simulated in {float(wall.group(2)):.0f} s")
    parts.append("plots")
    return dict(where="a clean clone" if clean else "this checkout",
                date=datetime.date.today().isoformat(), cores=os.cpu_count(),
                python=platform.python_version(), demo_min=demo_s / 60,
                demo_parts=", ".join(parts), test_min=test_s / 60,
                tests=pytest_counts(test_out) or "0 passed")


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m rcac_ros.tools.results.timings",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--clean", action="store_true",
                        help="run in a fresh clone of HEAD (install included), as a new user")
    parser.add_argument("--dry-run", action="store_true", help="print the figures, write nothing")
    args = parser.parse_args(argv)
    from rcac_ros.tools.results import page
    started, rev = datetime.datetime.now(datetime.timezone.utc), page.revision()
    load0, t0 = os.getloadavg()[0], time.monotonic()
    fields = measure(page.ROOT, args.clean)
    record = page.provenance("make readme-timings" if args.clean else
                             "python -m rcac_ros.tools.results.timings", started,
                             time.monotonic() - t0, load0, os.getloadavg()[0], rev=rev)
    print(TEMPLATE.format(**fields))
    if not args.dry_run:
        return page.store("timings", fields, record, "readme-timings")
    return 0


if __name__ == "__main__":
    sys.exit(main())
