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
The 3DM-GX2 protocol as bytes: no ROS, no serial port, no clock, no numpy.

The layout table (``layouts``) drives the command and record encoders and
decoders (``commands``); ``framing`` wraps them for the wire, wired or
wireless; ``parser`` finds frames in a byte stream; ``orientation`` and
``timer`` interpret what the records carry.
"""

from . import layouts, records
from .commands import (
    Command, decode_command, decode_record, encode_command, encode_record, layout_of,
)
from .errors import (
    ChecksumError, CodecError, DecodeError, EncodeError, LengthError, UnknownCommandError,
)
from .framing import (
    ACK, CommandPacket, DataPacket, encode_command_packet, encode_data_packet,
    encode_wired_record, MAX_ADDRESS, MIN_ADDRESS, NACK,
)
from .parser import (
    Ack, CommandStreamParser, Nack, ParserStats, RawCommand, RejectedPacket,
    SensorStreamParser,
)

__all__ = [
    'ACK', 'MAX_ADDRESS', 'MIN_ADDRESS', 'NACK', 'Ack', 'ChecksumError', 'CodecError', 'Command',
    'CommandPacket', 'CommandStreamParser', 'DataPacket', 'DecodeError', 'EncodeError',
    'LengthError', 'Nack', 'ParserStats', 'RawCommand', 'RejectedPacket', 'SensorStreamParser',
    'UnknownCommandError', 'decode_command', 'decode_record', 'encode_command',
    'encode_command_packet', 'encode_data_packet', 'encode_record', 'encode_wired_record',
    'layout_of', 'layouts', 'records',
]
