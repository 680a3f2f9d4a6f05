"""Argument types for coral-check's options: one message per mistake, everywhere.

Each function takes the text argparse hands over and returns the value, or raises
`argparse.ArgumentTypeError` with the message argparse prints after the option name.
"""

from __future__ import annotations

import argparse


def positive_int(text: str) -> int:
    """A whole number of at least 1 (state budgets, edge budgets, limits)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return value


def finite_number(text: str) -> float:
    """Any finite number (no ``nan``, no ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: '{text}'") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"not a finite number: '{text}'")
    return value


def positive_float(text: str) -> float:
    """A finite number above 0 (time limits in seconds)."""
    value = finite_number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("must be more than 0")
    return value


def non_negative_float(text: str) -> float:
    """A finite number of at least 0."""
    value = finite_number(text)
    if value < 0:
        raise argparse.ArgumentTypeError("must be 0 or more")
    return value
