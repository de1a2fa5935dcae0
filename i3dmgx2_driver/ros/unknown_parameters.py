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
Name every parameter override the node does not declare.

rclpy silently ignores ``-p data_rat:=200.0`` (a typo of ``data_rate``): the
user believes the rate is set. The overrides given on the command line or
in a params file (under ``/**`` or the node's name) are in
``node._parameter_overrides``; any of them the node does not declare, and
that is not one of the driver's own names (they may not be declared yet when
a required one is missing), is named in one warning, with the closest real
name when one is close. rclpy's own parameters (``use_sim_time``,
``start_type_description_service``) are declared by rclpy itself, so they
are never reported. Only a missing required parameter stops the node; an
unknown one does not.
"""

from collections.abc import Iterable
import difflib

from rclpy.node import Node

#: How alike two names must be (difflib's ratio) for "did you mean".
CLOSE_ENOUGH = 0.6


def unknown_names(given: Iterable[str], known: Iterable[str]) -> list[tuple[str, str | None]]:
    """
    Return (unknown name, closest known name or None) for each given name not known.

    Pure, sorted by name, so that messages come in a stable order.
    """
    known = sorted(set(known))
    out = []
    for name in sorted(set(given) - set(known)):
        close = difflib.get_close_matches(name, known, n=1, cutoff=CLOSE_ENOUGH)
        out.append((name, close[0] if close else None))
    return out


def message(name: str, closest: str | None) -> str:
    """One line about one unknown parameter: what it is, and what was probably meant."""
    meant = f" (did you mean '{closest}'?)" if closest else ''
    return (f"unknown parameter '{name}'{meant}: ignored, the driver has no such parameter "
            f'(ros2 param list shows those it has)')


def warn_unknown_parameters(node: Node, expected: Iterable[str]) -> list[str]:
    """
    Warn once about each override ``node`` does not declare; return the messages.

    ``expected`` are the names the entry point declares (or is about to):
    the rest of the known names are those ``node`` has declared so far,
    rclpy's own among them.
    """
    # rclpy offers no public view of the overrides it was given (-p, params files):
    # this one read of its private field is the only one in the driver (the
    # parameters themselves go through public API, parameters.py), and
    # test/test_parameter_typing.py fails loudly if rclpy renames or reshapes it.
    given = getattr(node, '_parameter_overrides', None) or {}
    declared = node.list_parameters([], 0).names
    lines = [message(name, closest)
             for name, closest in unknown_names(given, [*expected, *declared])]
    for line in lines:
        node.get_logger().warning(line)
    return lines
