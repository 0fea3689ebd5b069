"""Where the real robot URDFs of the PyPI package ``example-robot-data`` live (if installed)."""

import glob
import os
import site
import sys


def example_robots_dir():
    """example-robot-data's ``robots`` directory (its cmeel prefix in site-packages), or None."""
    try:
        import example_robot_data
        path = example_robot_data.getModelPath("panda_description/urdf/panda.urdf")
        if os.path.isdir(os.path.join(path, "panda_description")):
            return path
    except (ImportError, AttributeError, OSError, ValueError):
        pass
    for root in list(site.getsitepackages()) + [site.getusersitepackages()] + sys.path:
        hits = glob.glob(os.path.join(root, "cmeel.prefix", "share", "example-robot-data",
                                      "robots"))
        if hits:
            return hits[0]
    return None


def example_robot_urdf(relative):
    """The path of ``relative`` (e.g. ``panda_description/urdf/panda.urdf``), or None."""
    root = example_robots_dir()
    path = None if root is None else os.path.join(root, relative)
    return path if path is not None and os.path.isfile(path) else None
