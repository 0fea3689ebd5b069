"""Why the adaptation of eq 24 is frozen: the operator, the starvation guard, a recovery.

The operator's ``~/set_adaptation`` (:mod:`.estimate_services`), the starvation guard
(:mod:`.starvation`, doc/failsafe.md "Starved machine") and the recovery after a long spell
without the law's effort (:mod:`.control`) each hold their own reason; the law is frozen
while any holds (their OR). So the guard's recovery does not undo an operator's freeze,
and an operator's resume during starvation does not undo the guard's freeze: the
adaptation comes back when none holds. All are called from the node's one
executor-and-loop thread.
"""


class AdaptationFreeze:
    """The reasons that freeze the adaptation of the core controller ``ctrl``.

    Attributes
    ----------
    reasons : set of str
        Those that hold now (:attr:`USER`, :attr:`STARVED`, :attr:`RECOVERING`); empty:
        adapting.
    """

    USER, STARVED, RECOVERING = "user", "starved", "recovering"

    def __init__(self, ctrl):
        self.ctrl = ctrl
        self.reasons = set()

    def freeze(self, reason, frozen):
        """Set (``frozen``) or lift one ``reason``; the law follows their OR."""
        if frozen:
            self.reasons.add(reason)
        else:
            self.reasons.discard(reason)
        adapting = not self.reasons
        if adapting != self.ctrl.adapting:
            self.ctrl.set_adaptation(adapting)
