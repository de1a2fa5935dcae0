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
* ``percentiles``: a sample's percentile and summary.
* ``campaign``: the soak and fault campaign (``benchmarks/soak.py`` runs it
  for minutes, ``test/test_soak_short.py`` for half a minute): its settings
  in ``campaign_config``, its faults in ``fault_driver``, the truth in
  ``campaign_truth``, its subscriber in ``campaign_listener``, a run's data in
  ``campaign_data``; ``campaign_analysis`` judges it from ``read_windows``,
  ``campaign_match``, ``campaign_stamps``, ``campaign_counters`` and
  ``campaign_health`` into ``campaign_result`` and ``campaign_report``.
* ``run_config``: the settings the campaign, the long soak and the node fuzz share.
* ``long_soak``: the campaign's legs over every stream for an hour, from
  ``soak_plan`` (settings, legs), ``soak_nodes`` (the node processes),
  ``soak_leg`` (one leg), ``soak_recovery`` (data back after a fault),
  ``process_sampler`` (RSS, descriptors, threads, slopes) and ``soak_report``.
* ``hostile``: a hostile base station (its attacks' bytes in
  ``packet_mutation``, its oracle in ``hostile_oracle``); ``node_fuzz``
  fuzzes the running node through it.
* ``fuzz_checks``: the codec's properties on one input (the fuzzer in
  ``benchmarks/fuzz_parser.py`` and ``test/test_fuzz_regressions.py``).
* ``stamp_runs``: stamps against the simulator's truth, and their check.

The tests find it through pytest's ``pythonpath = .``; the benchmarks put
the repository on ``sys.path`` themselves (``benchmarks/bench_common.py``).
"""
