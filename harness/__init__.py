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
What the tests and the benchmarks share; not installed with the driver.

``test/`` and ``benchmarks/`` never import each other: what both need is
here, one module per concern, and they import it and the driver package.
This package may import ``i3dmgx2_driver``; nothing in ``i3dmgx2_driver``
imports it. Each module's docstring says more.

* ``processes``: the node, the simulated device and a subscriber, each in a
  process of its own, an rclpy subscriber and lifecycle client in this one,
  and a ROS domain of the run's own; ``sim_process``, ``subscriber`` and
  ``instrumented_node`` are the programs those processes run.
* ``campaign``, ``fault_driver``, ``campaign_verdict``, ``long_soak``: the
  fault campaign and the long soak (its pieces, its faults, its verdict, its
  run, one leg or an hour of them); ``process_sampler`` samples the node
  processes' RSS, descriptors and threads for it and for
  ``benchmarks/memory_curve.py``.
* ``hostile``: a hostile base station, its attacks' bytes and its oracle.
* ``fuzz_checks``: the codec's properties on one input.
* ``stamp_runs``: stamps against the simulator's truth, and their check.
* ``shutdown_trials``: a signal at a random moment of every phase, on nodes
  forked by ``node_forks``.

The tests find it through pytest's ``pythonpath = .``; the benchmarks put
the repository on ``sys.path`` themselves (``benchmarks/bench_common.py``).
"""
