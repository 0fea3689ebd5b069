"""Count the arithmetic of one controller step, exactly, by running the kernel's own source.

The compiled kernels are plain scalar Python under numba. With
``NUMBA_DISABLE_JIT=1`` they run as Python, and fed arrays of :class:`Counted`
numbers (a ``float`` that tallies every ``*``, ``/``, ``+`` and ``-`` it takes
part in) they report the operations of the very code that runs compiled.
Operations between two untracked constants (e.g. ``0.0 + 0.0`` on the first
link, where the base is at rest) are not counted: they fold away in the
compiled code too. :func:`count_step` runs in a subprocess so that the
caller's compiled kernels are untouched.
"""

import json
import os
import subprocess
import sys

import numpy as np

_COUNTS = {"mul": 0, "div": 0, "add": 0}


class Counted(float):
    """A float that counts the arithmetic operations it takes part in."""

    def _op(self, kind, value):
        _COUNTS[kind] += 1
        return Counted(value)

    def __mul__(self, o):
        return self._op("mul", float(self) * float(o))

    __rmul__ = __mul__

    def __truediv__(self, o):
        return self._op("div", float(self) / float(o))

    def __rtruediv__(self, o):
        return self._op("div", float(o) / float(self))

    def __add__(self, o):
        return self._op("add", float(self) + float(o))

    __radd__ = __add__

    def __sub__(self, o):
        return self._op("add", float(self) - float(o))

    def __rsub__(self, o):
        return self._op("add", float(o) - float(self))

    def __neg__(self):
        return Counted(-float(self))

    def __pos__(self):
        return self


def _counted(arr):
    out = np.empty(arr.shape, dtype=object)
    out.flat[:] = [Counted(v) for v in arr.flat]
    return out


def _counting(kernel):
    """``kernel`` run on :class:`Counted` copies of its array arguments.

    The results are written back into the caller's arrays, so the controller's state
    advances as in a plain step.
    """
    def run(*args):
        counted = [_counted(a) if isinstance(a, np.ndarray) else a for a in args]
        out = kernel(*counted)
        for a, c in zip(args, counted):
            if isinstance(a, np.ndarray) and a.flags.writeable:
                a[...] = c.astype(float)
        return out
    return run


#: kind -> options of the recursive controller ("slotine_li": the baseline)
KINDS = {
    "rcac": {},
    "rcac_power": {"channels": [1, "power"]},
    "rcac_all": {"channels": "all"},
    "rcac_all_explicit": {"channels": "all", "update": "explicit"},
    "rcac_least_squares": {"adaptation": "least_squares", "forgetting": 0.5},
    "slotine_li": None,
}


def _count_in_process(kind, n_links):
    from rcac_ros.core import composite, css_arm, slotine_li
    model = css_arm().repeated(max(1, n_links // 7))
    rng = np.random.default_rng(0)
    vecs = rng.normal(size=(5, model.n)) * 0.1
    theta_hat0 = rng.normal(size=(model.n, 13))
    # the controllers call their kernel by its module name: count through the public step
    if KINDS[kind] is not None:
        composite.rcac_step_kernel = _counting(composite.rcac_step_kernel)
        composite.paper_step = _counting(composite.paper_step)
        c = composite.RecursiveCompositeController(model, theta_hat0=theta_hat0,
                                                   **KINDS[kind])
    else:
        slotine_li.slotine_li_step_kernel = _counting(slotine_li.slotine_li_step_kernel)
        c = slotine_li.SlotineLiCompositeController(model, theta_hat0=theta_hat0)
    c.step(*vecs)                   # the first step initialises the filters: not counted
    for k in _COUNTS:
        _COUNTS[k] = 0
    c.step(*vecs)
    return dict(_COUNTS)


def count_step(kind="rcac", n_links=7):
    """Operations of one steady-state step: ``{"mul": .., "div": .., "add": ..}``.

    Parameters
    ----------
    kind : str
        A key of :data:`KINDS`.
    n_links : int
        A multiple of 7 (the CSS arm repeated).
    """
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, "-m", "rcac_ros.tools.bench.opcount", kind,
                          str(n_links)], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    print(json.dumps(_count_in_process(sys.argv[1], int(sys.argv[2]))))
