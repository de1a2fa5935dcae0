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
A sample's path allocates nothing that outlives the sample.

The garbage collector runs when the objects it tracks (tuples, lists,
instances) grow by hundreds; a path that leaves none behind never triggers
it, and with the start-up heap frozen a collection that other work triggers
has next to nothing to walk. The real node runs in this process (real rclpy,
not spinning: the executor's own work is not the sample's path) against the
simulator in a process of its own; with the collector switched off for the
window, the count of tracked objects is read before and after hundreds of
published samples.
"""

import gc
import subprocess
import sys
import time

from i3dmgx2_driver.ros.imu_node import ImuDriverNode
import rclpy
from rclpy.parameter import Parameter
from ros_harness import isolate_ros_domain, REPO, ros_env

#: Samples measured, and the most tracked objects they may leave behind in all: the device
#: clock keeps one point per second of data (a few in the window), nothing per sample.
SAMPLES = 300
ALLOWED_GROWTH = 20


def test_published_samples_leave_no_tracked_objects_behind():
    isolate_ros_domain()
    sim = subprocess.Popen([sys.executable, '-m', 'i3dmgx2_driver.simulator', '--seed', '61'],
                           stdout=subprocess.PIPE, stdin=subprocess.PIPE, text=True,
                           env=ros_env(), cwd=REPO)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = None
    try:
        port = sim.stdout.readline().split(': ', 1)[1].strip()
        node = ImuDriverNode(context=context, parameter_overrides=[
            Parameter('port', value=port), Parameter('address', value=95),
            Parameter('publish_mag', value=False)])
        deadline = time.monotonic() + 30.0
        while node.core.stats.published < 100 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert node.core.stats.published >= 100, 'the node did not stream'
        gc.collect()
        gc.disable()
        try:
            published, tracked = node.core.stats.published, gc.get_count()[0]
            while node.core.stats.published < published + SAMPLES \
                    and time.monotonic() < deadline + 30.0:
                time.sleep(0.05)
            published, tracked = (node.core.stats.published - published,
                                  gc.get_count()[0] - tracked)
        finally:
            gc.enable()
        assert published >= SAMPLES
        assert tracked <= ALLOWED_GROWTH, \
            f'{tracked} tracked objects left behind by {published} samples'
    finally:
        if node is not None:
            node.shutdown()
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        sim.terminate()
        sim.wait(10)
