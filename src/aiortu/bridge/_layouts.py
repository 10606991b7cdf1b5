"""The topic layouts by name: the one a configuration's `[topics]` asks for."""

from __future__ import annotations

from aiortu.bridge._config import TopicLayout
from aiortu.bridge._plain_layout import PlainLayout
from aiortu.bridge._sparkplug import SparkplugLayout
from aiortu.bridge._state import Layout

__all__ = ("make_layout",)


def make_layout(topics: TopicLayout) -> Layout:
    """The layout `topics.layout` names (one of [`LAYOUTS`][aiortu.bridge.LAYOUTS])."""
    if topics.layout == "sparkplug":
        return SparkplugLayout(topics)
    return PlainLayout(topics, discovery=topics.layout == "home-assistant")
