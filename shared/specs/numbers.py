"""Numbers as users write them: a number too small for a float (`1e-400`) parses to 0.0 and
would pass a bound such as `friction ≥ 0` as a value nobody gave, so it is refused where text
becomes a number (REST bodies and forms, the command line)."""

from __future__ import annotations

import argparse
import math
import sys

UNDERFLOW_MESSAGE = (f"Input is too small for a float: it would be used as 0.0 (the least "
                     f"magnitude is {sys.float_info.min:.3g}); give 0 or a larger number")


def underflows(text: str) -> bool:
    """A number written with a non-zero digit that parses to 0.0 or below the least normal
    float (`1e-400`): what would be used is not what was given."""
    try:
        value = float(text)
    except ValueError:
        return False
    if not math.isfinite(value) or (value != 0.0 and abs(value) >= sys.float_info.min):
        return False
    mantissa = text.strip().lower().split("e")[0]
    return any(digit in mantissa for digit in "123456789")


def cli_number(text: str) -> float:
    """argparse `type=` for a finite number that does not underflow."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    if underflows(text):
        raise argparse.ArgumentTypeError(f"{text!r}: {UNDERFLOW_MESSAGE}")
    return value
