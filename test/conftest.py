"""The tests' root: ``test/`` is on ``sys.path`` (pytest's prepend import mode), so the
shared helpers import as ``from chains import random_chain, to_pin``."""
