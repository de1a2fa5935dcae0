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
Every sensor the node serves, each a :class:`~.driver_core.DriverCore`, on one port.

With one sensor (``address``) the set holds one core that opens its port
itself, exactly as the driver always did: nothing on its hot path changes.
With several (``addresses``) the cores share one
:class:`~..device.shared_port.SharedPort` (one reader thread routing each
packet to its sensor's core) and one raw capture of the port; each core has
its own publishers, clock, counters, supervisor, services and diagnostics
(sensor_set.py says how they are named). Stopping stops them all at once, so
that several sensors stop as fast as one.
"""

from collections.abc import Callable
import threading

from rclpy.node import Node

from .driver_core import CoreRole, device_config, DriverCore, Probes, SensorSlot
from .parameters import DriverConfig
from .publishers import Publishers
from ..capture import RawCapture
from ..device.hot_path import HotPathObserver
from ..device.port import check_port_path, PortError, SerialPort
from ..device.shared_port import SharedPort


class DriverSet:
    """
    The cores of every sensor in ``config`` on ``node``, sharing their port if several.

    ``publishers``, if given, holds each sensor's (a managed node's lifecycle
    publishers, in the order of ``config.sensors``); the other arguments are
    handed to every core (see DriverCore).
    """

    def __init__(self, node: Node, config: DriverConfig,
                 publishers: list[Publishers] | None = None, publishing: bool = True,
                 refusal: Callable[[], str] | None = None,
                 timings: HotPathObserver | None = None,
                 port_factory: Callable[..., SerialPort] = SerialPort) -> None:
        check_port_path(config.port)
        sensors = config.sensors
        self.config = config
        self.shared: SharedPort | None = None
        capture: RawCapture | None = None
        if len(sensors) > 1:
            capture = RawCapture(
                config.capture_file, node.get_logger(), port=config.port,
                address=sensors[0].address, baud=config.baud, wireless=config.wireless,
                node=node.get_fully_qualified_name())
            self.shared = SharedPort(
                device_config(config, sensors[0]), node.get_logger(), port_factory,
                capture.on_bytes if capture.active else None, timings)
        self._capture = capture
        probes = Probes(timings, port_factory)
        self.cores = [
            DriverCore(node, config,
                       CoreRole(publishers[i] if publishers else None, publishing, refusal),
                       probes, SensorSlot(sensor, self.shared, capture))
            for i, sensor in enumerate(sensors)]

    @property
    def several(self) -> bool:
        """Whether the set serves several sensors on a shared port."""
        return self.shared is not None

    @property
    def fatal_error(self) -> PortError | None:
        """Return why the port can never work, once a supervisor found out (else None)."""
        return next((core.fatal_error for core in self.cores if core.fatal_error), None)

    def start(self) -> None:
        """Start every sensor's supervisor (the plain node: stream, recover, forever)."""
        for core in self.cores:
            core.supervisor.start()

    def set_publishing(self, on: bool) -> None:
        """Publish the records (a managed node while active), or only count them."""
        for core in self.cores:
            core.set_publishing(on)

    def shutdown(self, report: bool = True) -> None:
        """Stop every stream and close the port, the sensors at once (bounded in time)."""
        if len(self.cores) == 1:
            self.cores[0].shutdown(report)
            return
        threads = [threading.Thread(target=core.shutdown, args=(report,),
                                    name=f'gx2-stop-{core.sensor.address}')
                   for core in self.cores]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(5.0)
        if self._capture is not None:
            self._capture.close()

    def destroy(self) -> None:
        """Remove every core's services from the node (after shutdown)."""
        for core in self.cores:
            core.destroy()
