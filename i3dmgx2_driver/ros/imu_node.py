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
The driver node: a plain rclpy node that streams from the moment it starts.

Everything the driver does is in :class:`~.driver_core.DriverCore`, shared
with the managed node: this node declares the parameters (a bad one stops
it at once, and a name it does not know is named), makes the core (a port
path that can never work stops it at once too), publishes the diagnostics
and starts the supervisor, which opens the port, and keeps the stream going,
retrying forever.
"""

from collections.abc import Callable

from rclpy.node import Node

from .diagnostics import DiagnosticsPublisher
from .driver_core import DriverCore, DriverSet, load_config
from .parameters import DriverConfig
from ..device.port import PortError


class ImuDriverNode(Node):
    """Publish the records of the chosen stream as sensor_msgs/Imu and MagneticField."""

    def __init__(self, node_name: str = 'i3dmgx2_driver', **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        #: Called when the port can never work (main.run wakes its thread with it).
        self.on_done: Callable[[], None] = lambda: None
        self.config: DriverConfig = load_config(self)
        #: Every sensor's core (one, unless ``addresses`` lists several: DriverSet).
        self.drivers = DriverSet(self, self.config, on_fatal=self._fatal)
        self.core: DriverCore = self.drivers.cores[0]
        self.diagnostics = [
            DiagnosticsPublisher(self, lambda core=core: core,
                                 sensor=core.sensor.name if self.drivers.several else '')
            for core in self.drivers.cores]
        self.drivers.start()

    def _fatal(self) -> None:
        self.on_done()  # whatever run() set it to since

    #: Whether the node is done by itself: never (it runs until a signal).
    finished = False

    @property
    def fatal_error(self) -> PortError | None:
        """Why the port can never work, once the supervisor found out (main exits 2)."""
        return self.drivers.fatal_error

    def shutdown(self) -> None:
        """Stop the diagnostics and the device streams, and close the port (bounded in time)."""
        for diagnostics in self.diagnostics:
            diagnostics.stop()
        self.drivers.shutdown()
