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
A ROS user installs it with rosdep, and the build farm releases it with bloom.

Both read package.xml's keys, and both fail on one the ROS distribution does
not know (``ament_python`` was such a key): ``rosdep install`` leaves the
user without the dependencies, and ``bloom-generate`` stops the release.
So the real tools run here, offline, against the snapshot of ros/rosdistro
in ``../shared/rosdistro`` (its README shows how), for each distribution the
package is released into: rosdep resolves every key, and bloom writes
``debian/`` with no warning but the one it always gives (the releaser
history lives in the release repository, which bloom-generate never sees).
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys
from xml.etree import ElementTree

import pytest

REPO = Path(__file__).resolve().parents[1]
#: The snapshot of ros/rosdistro beside the repository; a plain clone has none.
ROSDISTRO = REPO.parent / 'shared' / 'rosdistro'
DISTROS = ('jazzy', 'kilted')
OS_NAME, OS_VERSION = 'ubuntu', 'noble'
#: What bloom reads: package.xml, the changelog, and debian/ (the udev rule it installs).
RELEASED = ('package.xml', 'CHANGELOG.rst', 'debian')
#: The one warning bloom-generate gives every package (bloom-release keeps that history).
BLOOM_ALWAYS_WARNS = 'No historical releaser history'

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (ROSDISTRO / 'index-v4.yaml').is_file(),
                       reason=f'no snapshot of ros/rosdistro at {ROSDISTRO} to resolve against'),
]


def _tool(name: str) -> str:
    """Return the path of ``name`` from requirements-dev.txt (beside this python, or on PATH)."""
    path = os.path.join(os.path.dirname(sys.executable), name)
    found = path if os.path.exists(path) else shutil.which(name)
    assert found, f'{name} is missing: it is part of requirements-dev.txt (pip install {name})'
    return found


@pytest.fixture(scope='module')
def rosdep_env(tmp_path_factory) -> dict[str, str]:
    """Return the environment of a rosdep cache updated from the snapshot only (file:// URLs)."""
    base = tmp_path_factory.mktemp('rosdep')
    sources = base / 'sources.list.d'
    sources.mkdir()
    (sources / '20-default.list').write_text(
        ''.join(f'yaml file://{ROSDISTRO}/rosdep/{name}.yaml\n' for name in ('base', 'python')))
    # As on a fresh machine: with --ignore-src, rosdep takes the packages on these paths (the
    # venv's ROS wheels, under scripts/env.sh or colcon) as built from source, and skips them.
    env = {key: value for key, value in os.environ.items()
           if key not in ('AMENT_PREFIX_PATH', 'ROS_PACKAGE_PATH', 'CMAKE_PREFIX_PATH')}
    env.update(ROSDEP_SOURCE_PATH=str(sources),
               ROSDISTRO_INDEX_URL=f'file://{ROSDISTRO}/index-v4.yaml',
               ROS_HOME=str(base / 'ros_home'),
               PATH=os.pathsep.join((os.path.dirname(sys.executable), os.environ['PATH'])))
    update = subprocess.run([_tool('rosdep'), 'update'], env=env, capture_output=True,
                            text=True, timeout=120)
    assert update.returncode == 0, update.stdout + update.stderr
    return env


def _scratch_copy(tmp_path: Path) -> Path:
    """Copy what a release reads into ``tmp_path/src/i3dmgx2_driver``; return that folder."""
    package = tmp_path / 'src' / 'i3dmgx2_driver'
    package.mkdir(parents=True)
    for name in RELEASED:
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, package / name)
        else:
            shutil.copy2(source, package / name)
    return package


def _keys() -> set[str]:
    root = ElementTree.parse(REPO / 'package.xml').getroot()
    return {element.text.strip() for element in root if element.tag.endswith('depend')}


@pytest.mark.parametrize('distro', DISTROS)
def test_rosdep_resolves_every_key_of_package_xml(distro, rosdep_env, tmp_path):
    package = _scratch_copy(tmp_path)
    run = subprocess.run(
        [_tool('rosdep'), 'install', '--from-paths', str(package.parent), '--ignore-src',
         '--simulate', '--rosdistro', distro, f'--os={OS_NAME}:{OS_VERSION}'],
        env=rosdep_env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    # One package of the distribution, or of Ubuntu, for each key: none left out.
    installs = [line for line in run.stdout.splitlines() if 'apt-get install' in line]
    assert len(installs) == len(_keys()), run.stdout


@pytest.mark.parametrize('distro', DISTROS)
def test_bloom_generates_the_debian_packaging_without_a_warning(distro, rosdep_env, tmp_path):
    package = _scratch_copy(tmp_path)
    # bloom's update check asks PyPI unless ~/.bloom exists; it logs each run in ~/.bloom_logs.
    home = tmp_path / 'home'
    home.mkdir()
    (home / '.bloom').touch()
    run = subprocess.run(
        [_tool('bloom-generate'), 'rosdebian', '--ros-distro', distro, '--os-name', OS_NAME,
         '--os-version', OS_VERSION],
        cwd=package, env=dict(rosdep_env, HOME=str(home)), capture_output=True, text=True,
        timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    # Its warnings, as its log has them ('[warning] ...'): whatever the terminal's colours.
    [log] = (home / '.bloom_logs').glob('bloom-generate_*.log')
    warnings = [line for line in log.read_text().splitlines()
                if '[warning]' in line and BLOOM_ALWAYS_WARNS not in line]
    assert warnings == [], run.stdout
    control = (package / 'debian' / 'control').read_text()
    assert f'Source: ros-{distro}-i3dmgx2-driver\n' in control, control
    version = ElementTree.parse(REPO / 'package.xml').getroot().findtext('version')
    changelog = (package / 'debian' / 'changelog').read_text()
    assert changelog.startswith(
        f'ros-{distro}-i3dmgx2-driver ({version}-0{OS_VERSION}) {OS_VERSION};'), changelog
    # The udev rule is kept: debhelper installs debian/udev to /lib/udev/rules.d/.
    assert (package / 'debian' / 'udev').read_bytes() == (REPO / 'debian' / 'udev').read_bytes()
