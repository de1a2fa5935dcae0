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
matplotlib, for the tools' figures, imported when a figure is drawn.

matplotlib is an optional extra, not a dependency of the package: on a
robot it would pull in a GUI stack the driver never uses. The node,
``discover``, ``bringup`` and every module they import never import it
(``test/test_package_xml.py`` checks that no module imports it at load
time, ``test/test_without_matplotlib.py`` runs them without it); the tools
import it here, when they draw, and say how to install it if it is
missing, still writing the files that need no figure (:func:`write_files`).
"""

from collections.abc import Callable, Sequence
import os
from pathlib import Path
import sys
from typing import Any

#: What to do when matplotlib is missing.
MATPLOTLIB_HINT = ('the plot tool needs matplotlib, an optional extra the driver does not '
                   'install: sudo apt install python3-matplotlib (with ROS), or pip install '
                   'matplotlib (pip install "i3dmgx2_driver[plot]" from a source checkout)')

#: Axis colours: x, y, z as the RGB convention of axes in RViz.
COLOURS = ('tab:red', 'tab:green', 'tab:blue')


class MatplotlibMissing(ImportError):
    """matplotlib is not installed; the message says how to install it."""


def agg_figure(**kwargs: Any) -> Any:
    """
    Return a matplotlib Figure on an Agg canvas, made with ``kwargs``.

    No pyplot: no display is ever needed or opened, no global state is kept,
    and the figure is freed with its last reference. Raises
    :class:`MatplotlibMissing` when matplotlib is not installed.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MatplotlibMissing(MATPLOTLIB_HINT) from exc
    return FigureCanvasAgg(Figure(**kwargs)).figure    # the canvas attaches itself


def have_matplotlib() -> bool:
    """Whether matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def write_files(tool: str, directory: str, texts: Sequence[tuple[str, str]], figure: str,
                draw: Callable[[str], Any]) -> list[str]:
    """Write each (name, text) into ``directory``, then ``draw`` ``figure``; return the paths."""
    os.makedirs(directory, exist_ok=True)
    written = [os.path.join(directory, name) for name, _ in texts]
    for path, (_, text) in zip(written, texts, strict=True):
        Path(path).write_text(text, encoding='utf-8')
    try:
        draw(os.path.join(directory, figure))
        written.append(os.path.join(directory, figure))
    except MatplotlibMissing as exc:
        print(f'{tool}: {figure} not drawn: {exc}', file=sys.stderr)
    return written
