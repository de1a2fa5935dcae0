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
imports it.

* ``processes``: the node, the simulated device and a subscriber, each in a
  process of its own (``NodeProcess``, ``SimProcess``, ``SubscriberProcess``),
  a subscriber and a lifecycle client in this process (``Listener``,
  ``LifecycleClient``), and a ROS domain of the run's own;
  ``sim_process``, ``subscriber`` and ``instrumented_node`` are the programs
  those processes run.
* ``campaign``: the soak and fault campaign's pieces (the truth, the
  subscriber, the node process and its counters), its faults in
  ``fault_driver``; ``campaign_verdict`` holds the settings the campaign,
  the long soak and the node fuzz share, and judges what a run produced (the
  checks and the report), for the campaign and the long soak alike.
* ``long_soak``: the campaign's run as legs over every stream for an hour
  (``benchmarks/soak.py --every-stream``), and the campaign itself as one
  plain leg (``run_campaign``: ``benchmarks/soak.py`` for minutes,
  ``test/test_soak_short.py`` for half a minute); its node processes sampled
  by ``process_sampler`` (RSS, descriptors, threads, slopes;
  ``benchmarks/memory_curve.py`` samples with it too).
* ``hostile``: a hostile base station, its attacks' bytes and its oracle;
  ``benchmarks/fuzz_node.py`` fuzzes the running node through it.
* ``fuzz_checks``: the codec's properties on one input (the fuzzer in
  ``benchmarks/fuzz_parser.py`` and ``test/test_fuzz_regressions.py``).
* ``stamp_runs``: stamps against the simulator's truth, and their check.
* ``shutdown_trials``: a signal at a random moment of every phase, on nodes
  forked by ``node_forks``.

The tests find it through pytest's ``pythonpath = .``; the benchmarks put
the repository on ``sys.path`` themselves (``benchmarks/bench_common.py``).
"""
