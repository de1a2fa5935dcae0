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
A check's verdict, and a run's verdicts with its report.

Apart from the analysis, since the long soak's nodes, sampler and report
make checks of their own, and would not import the analysis for them.
"""

import dataclasses
from typing import NamedTuple


class Check(NamedTuple):
    """One pass/fail verdict with its evidence."""

    name: str
    ok: bool
    detail: str


@dataclasses.dataclass
class CampaignResult:
    """The verdicts and the report of one run."""

    checks: list[Check]
    report: str
    #: The run's figures by name (sent, published, received, missing, ...), for a summary.
    figures: dict = dataclasses.field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Whether every check passed."""
        return all(check.ok for check in self.checks)

    def failures(self) -> list[Check]:
        """Return the checks that failed."""
        return [check for check in self.checks if not check.ok]


def verdict(name: str, ok: object, detail: str) -> Check:
    """Return a check, its ``ok`` a bool whatever the test gave (a count, a list, None)."""
    return Check(name, bool(ok), detail)
