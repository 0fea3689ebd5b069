"""Resolve a model argument: a preset name, a YAML model file, or a URDF (file or XML).

One reading of the ``model`` and ``robot_description`` parameters of the nodes and of
``rcac inspect --model``.
"""

import os

from rcac_ros.errors import ConfigError
from .model import PRESETS, RobotModel
from .urdf import model_from_urdf

#: endings of a URDF file
URDF_SUFFIXES = (".urdf", ".xml")
#: endings of a YAML model file
YAML_SUFFIXES = (".yaml", ".yml")


def is_urdf(spec):
    """Whether ``spec`` names a URDF: XML text, or a path ending in ``.urdf``/``.xml``."""
    text = os.fspath(spec)
    return text.lstrip().startswith("<") or text.endswith(URDF_SUFFIXES)


def load_model(spec, base_link=None, tip_link=None):
    """The :class:`RobotModel` that ``spec`` names.

    Parameters
    ----------
    spec : str or os.PathLike
        A preset name (:data:`~rcac_ros.core.model.PRESETS`), a YAML model file
        (``.yaml``/``.yml``, or any path with a directory), a URDF file (``.urdf``/``.xml``)
        or the URDF XML itself.
    base_link, tip_link : str, optional
        The URDF chain (see :func:`~rcac_ros.core.urdf.model_from_urdf`).

    Raises
    ------
    ConfigError
        An unknown name, a missing file, or a file that cannot be read.
    ModelError
        If the values are not physically valid.
    """
    text = os.fspath(spec)
    if text in PRESETS:
        return PRESETS[text]()
    if is_urdf(text):
        return model_from_urdf(text, base_link=base_link, tip_link=tip_link)
    if text.endswith(YAML_SUFFIXES) or os.path.sep in text:
        if os.path.isdir(text):
            raise ConfigError(f"{text!r} is a directory, not a model file")
        if not os.path.isfile(text):
            raise ConfigError(f"no such file {text!r}")
        return RobotModel.from_yaml(text)
    raise ConfigError(f"unknown model {text!r} (presets: {', '.join(PRESETS)}, or a path to a "
                      ".yaml model file or a URDF)")
