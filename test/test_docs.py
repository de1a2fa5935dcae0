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
The documentation of the parameters cannot drift from their declarations.

The README's table is what ``scripts/parameter_table.py`` prints from the
parameter table, and the shipped params file names every parameter, with
values that are valid defaults.
"""

import os
import runpy

from i3dmgx2_driver.ros.parameters import _REQUIRED, SPECS
import pytest
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_readme_parameter_table_is_generated_from_the_code():
    generator = runpy.run_path(os.path.join(REPO, 'scripts', 'parameter_table.py'))
    with open(os.path.join(REPO, 'README.md')) as handle:
        readme = handle.read()
    assert generator['table']() in readme, \
        'README is stale: paste the output of scripts/parameter_table.py'


@pytest.fixture(scope='module')
def params_file():
    with open(os.path.join(REPO, 'config', 'i3dmgx2.yaml')) as handle:
        text = handle.read()
    return text, yaml.safe_load(text)['/**']['ros__parameters']


def test_params_file_names_every_parameter(params_file):
    text, values = params_file
    for spec in SPECS:
        if spec.default is _REQUIRED:
            # Documented, deliberately left unset: there is no silent default.
            assert f'# {spec.name}:' in text
            assert spec.name not in values
        else:
            assert values[spec.name] == spec.default, spec.name
    assert set(values) <= {spec.name for spec in SPECS}
