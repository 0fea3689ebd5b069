"""The shipped PlotJuggler and Foxglove layouts (doc/tools.md, "rcac record") name fields that
exist in the
recorded topics: every curve resolves on a message of the topic's type, with the CSS arm's
sizes (7 joints, 7 x 13 estimates)."""

import json
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LAYOUTS = os.path.join(ROOT, "config", "layouts")


def _recorded():
    try:
        from rcac_ros.tools.bags.record import recorded_topics
    except ImportError:
        from rcac_ros.bag import recorded_topics
    return dict(recorded_topics())


def _sample(msgtype):
    """A message of ``msgtype`` with the demo's sizes, through rosbags' typestore."""
    from rosbags.typesys import get_typestore, Stores
    t = get_typestore(Stores.ROS2_JAZZY).types
    if msgtype == "std_msgs/msg/Float64":
        return t[msgtype](data=1.0)
    if msgtype == "std_msgs/msg/Float64MultiArray":
        return t[msgtype](layout=t["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0),
                          data=np.zeros(91))
    pytest.fail(f"no sample for {msgtype}")


def _resolve(topic_field, recorded, sep):
    topic, _, field = topic_field.rpartition(sep)
    assert topic in recorded, f"{topic} is not a recorded topic"
    msg = _sample(recorded[topic])
    name, _, index = field.partition("[")
    value = getattr(msg, name)
    if index:
        k = int(index.rstrip("]"))
        size = 91 if topic.endswith("parameter_estimates") else 7
        assert k < size, topic_field
        value = value[k]
    return float(value)


def test_plotjuggler_layout():
    recorded = _recorded()
    root = ET.parse(os.path.join(LAYOUTS, "plotjuggler.xml")).getroot()
    curves = [c.get("name") for c in root.iter("curve")]
    assert len(curves) == 7 + 7 + 4 + 1
    for name in curves:
        _resolve(name, recorded, "/")
    titles = " ".join(a.get("name") for a in root.iter("DockArea"))
    for word in ("tracking errors", "efforts", "estimates", "prediction error"):
        assert word in titles


def test_foxglove_layout():
    recorded = _recorded()
    doc = json.load(open(os.path.join(LAYOUTS, "foxglove.json")))
    paths = [p["value"] for panel in doc["configById"].values() for p in panel["paths"]]
    assert len(paths) == 7 + 7 + 4 + 1
    for path in paths:
        _resolve(path, recorded, ".")

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(
            node["second"])
    assert sorted(leaves(doc["layout"])) == sorted(doc["configById"])
