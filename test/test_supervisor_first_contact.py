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
The device layer's first-contact checks, for every entry point.

The plain node's supervisor thread and the managed node's configure phase
(:meth:`DeviceSupervisor.connect`) meet the same checks with the same words:
a path that is no serial port, and what the line carries when the device
does not answer. No ROS here: the supervisor against real paths and the
simulator.
"""

import threading

from i3dmgx2_driver.device.link import DeviceTimeout
from i3dmgx2_driver.device.port import check_port_path, PortNotSerial
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.status import State
from i3dmgx2_driver.device.supervisor import DeviceSupervisor
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from log_lines import Log
import pytest


def supervisor(port, address=95, **kwargs):
    log = Log()
    sup = DeviceSupervisor(DeviceConfig(port=port, address=address,
                                        reconnect_interval=0.2, **kwargs),
                           on_record=lambda packet, now, mono: None, log=log)
    return sup, log


def test_configure_refuses_a_file_with_the_words_of_the_check(tmp_path):
    path = tmp_path / 'passwd'
    path.write_text('root:x:0:0\n')
    with pytest.raises(PortNotSerial) as checked:
        check_port_path(str(path))
    sup, _ = supervisor(str(path))
    with pytest.raises(PortNotSerial) as configured:
        sup.connect()
    assert str(configured.value) == str(checked.value)
    assert sup.link is None


def test_the_supervisor_thread_gives_up_on_a_directory_once(tmp_path):
    fatal = []
    done = threading.Event()
    sup = DeviceSupervisor(DeviceConfig(port=str(tmp_path), address=95,
                                        reconnect_interval=0.1),
                           on_record=lambda packet, now, mono: None, log=Log(),
                           on_fatal=lambda exc: (fatal.append(exc), done.set()))
    sup.start()
    assert done.wait(10)
    assert sup.join(5), 'no retry: it can never work'
    assert len(fatal) == 1 and str(fatal[0]) == sup.status().fatal_error
    assert f'{tmp_path} is a directory, not a serial port' in str(fatal[0])
    assert sup.status().state is State.STOPPED
    sup.stop()


@pytest.mark.slow
def test_configure_of_a_silent_address_says_what_is_heard_instead():
    with PtySimulator(SimulatorConfig(seed=158, streaming_at_start=True)) as sim:
        sup, log = supervisor(sim.port, address=12)
        try:
            with pytest.raises(DeviceTimeout) as info:
                sup.connect()
        finally:
            sup.stop()
    text = str(info.value)
    assert text.startswith('node 12 is silent')
    assert 'observed on the line: packets arrive from node 95' in text
    assert 'set -p address:=95' in text
    assert not [m for level, m in log.lines if 'streaming' in m]


@pytest.mark.slow
def test_a_long_operation_with_the_stream_paused_is_no_silence():
    # Wired: the stop (0xFA) gets no reply, so for the operation's 4 s not one byte
    # comes; the driver asked for that quiet, and the observer must not call it silence.
    config = SimulatorConfig(wireless=False, seed=159)
    with PtySimulator(config) as sim:
        sup, log = supervisor(sim.port, wireless=False)
        sup.start()
        try:
            deadline = threading.Event()
            for _ in range(100):
                if sup.status().state is State.STREAMING:
                    break
                deadline.wait(0.1)
            assert sup.status().state is State.STREAMING, log.lines
            sup.run_paused(lambda link: deadline.wait(4.0))
            assert sup.status().state is State.STREAMING
        finally:
            sup.stop()
    assert not [m for level, m in log.lines if 'not one byte' in m], log.lines
    assert sup.status().advice == ''
