"""The guard of a starved machine: ``K_D`` scaled down while the loop's delay is past its margin.

Pure (no ROS): the controller node feeds it the steady time of each control step and the age
of the state the step uses (doc/failsafe.md, "Starved machine").

The delay of a step is the age of its state plus the time the previous effort was held
beyond one period. A delay that lasts diverges once it passes the delay margin of ``K_D``:
offline (``rcac bench delay-margin``, the CSS arm, the paper's motion) the margin falls as
1/K_D, the product staying at about :data:`MARGIN_PRODUCT`. The guard smooths the delay over
:data:`TAU` s of steady time (one late tick is a kick, not a lasting delay) and, while the
smoothed delay is past the margin divided by :data:`SAFETY`, asks for ``K_D`` scaled by
``margin / (SAFETY delay)`` (never below ``min_scale``): the scaled gain's own margin then
covers the delay twice. Control returns to the nominal gains once the smoothed delay has
stayed within that limit for ``recover_after`` s.
"""

import math

#: K_D (N m s/rad, the scalar of K_Di = K_D I6) times the largest effort delay (s) that still
#: tracked, measured offline with ``rcac bench delay-margin``'s loop: K_D = 1e4 tracked 4
#: periods late (8 ms) and diverged at 5; 3e3 tracked at 20 ms and diverged at 40 ms; 1e3
#: tracked at 80 ms (doc/failsafe.md, "Starved machine")
MARGIN_PRODUCT = 80.0
#: time constant of the smoothed delay, s
TAU = 0.5
#: the guard keeps the delay within margin / SAFETY of the gain it applies: at the product
#: itself a 20 ms delay on K_D = 4e3 diverged within 10 s (the edge lies between 60 and 100)
SAFETY = 2.0


def default_margin(K_D_max):
    """The delay margin of gains whose largest ``K_D`` is ``K_D_max``: product / K_D, s."""
    return MARGIN_PRODUCT / K_D_max


class DelayGuard:
    """The smoothed delay of the control steps and the ``K_D`` scale it calls for.

    Parameters
    ----------
    margin : float
        Delay margin of the gains, s (> 0).
    h : float
        Control period, s.
    recover_after : float
        The smoothed delay stays within the margin this long before the gains are nominal
        again, s.
    min_scale : float
        The smallest scale of ``K_D`` asked for, in (0, 1].

    Attributes
    ----------
    limit : float
        ``margin / SAFETY``, s: the smoothed delay the guard acts beyond.
    starved : bool
        The smoothed delay went past :attr:`limit` and has not stayed within it for
        ``recover_after`` s.
    scale : float
        The scale of ``K_D`` to use now (1 when not starved).
    delay : float
        The smoothed delay, s.
    spells : int
        How many times the guard went from nominal to starved.
    worst : float
        The largest smoothed delay seen, s.
    """

    def __init__(self, margin, h, recover_after=1.0, min_scale=0.02):
        self.margin, self.h = float(margin), float(h)
        self.limit = self.margin / SAFETY
        self.recover_after, self.min_scale = float(recover_after), float(min_scale)
        self.spells = 0
        self.worst = 0.0
        self.reset()

    def forget_gap(self):
        """The next step's gap is not a held effort (a spell of safe effort came between)."""
        self._last_ns = None

    def reset(self):
        """A fresh start (activation): nominal, no delay seen."""
        self.starved = False
        self.scale = 1.0
        self.delay = 0.0
        self._last_ns = None
        self._within_since_ns = None

    def step(self, now_ns, age_ns):
        """One control step at steady ``now_ns`` on a state ``age_ns`` old.

        Returns
        -------
        str or None
            ``"starved"`` when the guard enters the degraded mode at this step,
            ``"recovered"`` when it leaves it, else ``None``.
        """
        held = 0.0 if self._last_ns is None else max(0.0, (now_ns - self._last_ns) * 1e-9
                                                     - self.h)
        dt = self.h if self._last_ns is None else max(self.h, (now_ns - self._last_ns) * 1e-9)
        self._last_ns = now_ns
        delay = max(0.0, age_ns * 1e-9) + held
        self.delay += (1.0 - math.exp(-dt / TAU)) * (delay - self.delay)
        self.worst = max(self.worst, self.delay)
        event = None
        if self.delay > self.limit:
            self._within_since_ns = None
            if not self.starved:
                self.starved = True
                self.spells += 1
                event = "starved"
        elif self.starved:
            if self._within_since_ns is None:
                self._within_since_ns = now_ns
            elif (now_ns - self._within_since_ns) * 1e-9 >= self.recover_after:
                self.starved = False
                self._within_since_ns = None
                event = "recovered"
        self.scale = 1.0 if not self.starved else \
            max(self.min_scale, min(1.0, self.limit / max(self.delay, 1e-12)))
        return event
