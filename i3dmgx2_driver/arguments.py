# Copyright 2026 The i3dmgx2_driver Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Argument types every command line shares: numbers in a range, said plainly when not.

Here, beside the layers rather than in ``tools/``, so that the simulator's
command line (below the tools) uses the same types as discover and bringup.
"""

import argparse
from collections.abc import Callable
import math
from typing import TypeVar

Number = TypeVar('Number', int, float)


def in_range(convert: Callable[[str], Number], low: Number, high: Number,
             what: str) -> Callable[[str], Number]:
    """Return an argparse type: ``convert(text)`` in ``low..high``, else what is wrong."""
    def parse(text: str) -> Number:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not a {what}') from None
        if not low <= value <= high:
            wanted = f'at least {low:g}' if high == math.inf else f'{low:g}..{high:g}'
            raise argparse.ArgumentTypeError(f'{text!r}: give {wanted} ({what})')
        return value
    return parse


def seconds(low: float, high: float) -> Callable[[str], float]:
    """Return an argparse type for a number of seconds in ``low..high``."""
    return in_range(float, low, high, 'number of seconds')


def whole_number(low: int, high: int, what: str = 'whole number') -> Callable[[str], int]:
    """Return an argparse type for an integer in ``low..high`` (``what`` names it)."""
    return in_range(int, low, high, what)
