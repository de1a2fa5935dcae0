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
Errors raised by the codec.

One small hierarchy, so that callers can catch everything the codec raises
with ``CodecError`` while still telling a malformed byte string from a bad
argument. The stream parser never raises these: it counts and skips instead.
"""


class CodecError(ValueError):
    """Base class of every error the codec raises."""


class DecodeError(CodecError):
    """Bytes that do not form a valid command, record or packet."""


class ChecksumError(DecodeError):
    """A frame whose checksum does not match its contents."""


class LengthError(DecodeError):
    """A frame whose size does not match what its command byte requires."""


class UnknownCommandError(DecodeError):
    """A command or echo byte that the protocol does not define."""


class EncodeError(CodecError):
    """Arguments that cannot be encoded (out of range, wrong count or type)."""
