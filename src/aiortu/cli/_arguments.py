"""The argument types every command shares: each turns a command-line string into a value
or raises `argparse.ArgumentTypeError` naming the problem, which argparse prints
with the option's name before exiting with code 2."""

from __future__ import annotations

import argparse

__all__ = ("address", "positive_int", "probability", "seconds", "seconds_or_zero")


def address(text: str) -> int:
    """An address or a count: decimal or `0x` hex."""
    try:
        value = int(text, 16) if text.lower().startswith("0x") else int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a decimal or 0x hex number: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0: {text!r}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1, decimal or `0x` hex."""
    value = address(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1: {text!r}")
    return value


def seconds(text: str) -> float:
    """A number of seconds > 0."""
    value = _number_of_seconds(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0: {text!r}")
    return value


def seconds_or_zero(text: str) -> float:
    """A number of seconds >= 0."""
    value = _number_of_seconds(text)
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number of seconds >= 0: {text!r}")
    return value


def probability(text: str) -> float:
    """A probability, 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a probability: {text!r}") from None
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"must be a probability from 0 to 1: {text!r}")
    return value


def _number_of_seconds(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
