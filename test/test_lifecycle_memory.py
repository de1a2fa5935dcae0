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
A managed node's cleanup frees the core it drops, then and there.

The core (its publishers' callbacks, its threads' targets, its links) is
held in reference cycles, which only a full collection frees; the start-up
heap is frozen and a full collection comes seldom, so each cleanup's core
waited for one, and a lifecycle manager cycling the node saw its memory rise
by thousands of objects a cycle and fall in steps (the memory curve).
Real rclpy, the real managed node, against the simulator in this process.
"""

import gc
import time
import weakref

from harness.processes import isolate_ros_domain
from i3dmgx2_driver.ros.lifecycle_node import LifecycleDriverNode
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
import rclpy
from rclpy.parameter import Parameter

pytestmark = pytest.mark.slow


def test_a_cleanup_frees_the_core_it_drops():
    isolate_ros_domain()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with PtySimulator(SimulatorConfig(seed=91, truth_limit=0)) as sim:
            node = LifecycleDriverNode(
                context=context,
                parameter_overrides=[Parameter('port', value=sim.port),
                                     Parameter('address', value=95)])
            try:
                gc.freeze()  # as run() freezes the start-up heap
                cores = []
                for _ in range(3):
                    node.trigger_configure()
                    node.trigger_activate()
                    cores.append(weakref.ref(node.drivers))
                    gc.collect()  # the core is old now, as after hours of streaming
                    time.sleep(0.3)
                    node.trigger_deactivate()
                    node.trigger_cleanup()
                    assert node.drivers is None
                    assert cores[-1]() is None, 'the core dropped at cleanup is still held'
            finally:
                node.destroy_node()
                gc.unfreeze()
    finally:
        rclpy.try_shutdown(context=context)
