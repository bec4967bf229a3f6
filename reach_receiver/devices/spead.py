"""The iTPM spectrometer's SPEAD-64-48 packets: header decoding and channel order.

Layout of one datagram (all header words big-endian 64-bit)::

    word 0   SPEAD header: magic 0x53 | version 4 | item-pointer width 2 |
             heap-address width 6 | 16 reserved bits | number of items (8)
    word 1-8 items: 1 flag bit (1 = immediate value) | 15-bit item id | 48-bit value
    72..     payload, ``payload length`` bytes (1024): 128 little-endian 64-bit values

Items, in the order the iTPM sends them (the top 16 bits of each word, flag included)::

    0x8001 heap counter     bits 0-23 packet counter, bits 24-39 packet index
    0x8004 payload length   bytes of payload after the 72-byte header
    0x9027 sync time        Unix seconds of the firmware's last time sync
    0x9600 timestamp        spectrum time in units of 32768 x 2.5 ns after sync time
    0xA004 mode             bit 7 set = floating-point payload
    0xA002 channel info     bits 24-39 start channel, bits 16-23 channels included,
                            bits 8-15 start signal, bits 0-7 signals included
    0xA001 buffer id        bits 16-31 (reach_control also accepts id 0x2003 here)
    0x3300 payload offset   flag bit clear; bytes to skip at the start of the payload

Confirmed in ``lessju/reach_control`` ``spectrometer/spectra.py`` (floating-point
version, ``Spectra._decode_spead_header``, ``_add_packet_to_buffer``,
``_finalise_buffer``):

* the header words and the 16-bit ids with their flag bits above, 72-byte payload start;
  word 0 is checked there only by its top 16 bits (0x5304);
* start channel = bits 24-39 and start signal ("antenna") = bits 8-15 of 0x2002; buffer
  id = bits 16-31 of 0x2001; heap-counter split 24 / above; 0x3300 is read and ignored;
* timestamp to seconds: ``sync_time + timestamp * 32768 * 2.5e-9``; a spectrum is the
  set of packets sharing one timestamp;
* payload: 64-bit little-endian words, float64 (``'<d'``) in floating-point mode,
  int64 (``'<q'``) otherwise, NOT float32/uint32. So 2 inputs x 16384 channels x 8 bytes
  / 1024 = 256 packets, 128 values each;
* mode bit 7 must match the receiver's floating-point setting, else the packet is dropped;
* placement: with ``s = n_inputs // 2`` signals per FPGA, the packet's values go to row
  ``start_signal // s`` of a (2, s x n_channels) buffer at column ``start_channel x s``;
* reordering: columns are de-multiplexed (signal ``2 row + column % s``, position
  ``column // s``); only when ``s != 1`` the even/odd "descramble" follows (position
  ``m`` even -> channel ``m / 2``, odd -> ``m // 2 + n_channels / 2``); then, in
  floating-point mode, bit reversal of the 14-bit channel index. For REACH's 2 inputs
  (``s == 1``) that leaves bit reversal alone: design.md's "interleaved even/odd" applies
  to the 4-signal integer firmware, not to the 2-input floating-point one.

Confirmed in SKA ``ska-low-mccs-daq`` (``SPEAD.h``, ``ChannelisedData.cpp``): the header
word's byte fields, the 16/8/8 split of 0x2002 (including the "included" counts), the
packet counter / packet index split of 0x0001, and that 0x3300's value is an offset from
the end of the items to the first data byte (data length = payload length - offset);
the mode item sits fifth.

Assumed (not in either source): the low bits of the mode value (the simulator sends
0x86, SKA's "integrated channel" mode 0x6 plus the float bit; only bit 7 is checked);
the meaning of the heap counter for REACH (the simulator puts a per-spectrum counter in
bits 0-23 and the packet's index in bits 24-39; the receiver records it and groups
packets by timestamp as reach_control does); that the timestamp marks the start of the
spectrum's integration.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from reach_receiver.errors import ProtocolError

MAGIC = 0x53
VERSION = 4
ITEM_POINTER_WIDTH = 2
HEAP_ADDRESS_WIDTH = 6
N_ITEMS = 8
HEADER_BYTES = 8 + 8 * N_ITEMS
PAYLOAD_BYTES = 1024
PACKET_BYTES = HEADER_BYTES + PAYLOAD_BYTES
VALUE_BYTES = 8
DEFAULT_PORT = 4660
TIMESTAMP_UNIT_S = 32768 * 2.5e-9
"""Seconds per timestamp count: one 32768-sample frame at 400 MS/s (reach_control)."""

HEADER_WORD = (
    (MAGIC << 56) | (VERSION << 48) | (ITEM_POINTER_WIDTH << 40) | (HEAP_ADDRESS_WIDTH << 32)
) | N_ITEMS
IMMEDIATE = 0x8000
HEAP_COUNTER = 0x0001
PAYLOAD_LENGTH = 0x0004
SYNC_TIME = 0x1027
TIMESTAMP = 0x1600
MODE = 0x2004
CHANNEL_INFO = 0x2002
BUFFER_ID = 0x2001
BUFFER_ID_ALT = 0x2003
PAYLOAD_OFFSET = 0x3300
MODE_FLOATING_POINT = 0x80
SIMULATED_MODE = 0x06
VALUE_MASK = (1 << 48) - 1

ITEM_ORDER = (
    HEAP_COUNTER,
    PAYLOAD_LENGTH,
    SYNC_TIME,
    TIMESTAMP,
    MODE,
    CHANNEL_INFO,
    BUFFER_ID,
    PAYLOAD_OFFSET,
)
"""Item ids in the order the iTPM sends them (SKA reads the mode as the fifth item)."""
WIRE_IDS = tuple(i if i == PAYLOAD_OFFSET else IMMEDIATE | i for i in ITEM_ORDER)
"""The top 16 bits of each item word as sent: flag bit set except for 0x3300."""

_WORDS = struct.Struct(">9Q")
_IDS = struct.Struct(">8x" + "H6x" * N_ITEMS)


@dataclass(frozen=True, slots=True)
class SpeadHeader:
    """The decoded items of one packet (field names follow the table in the module doc)."""

    heap_counter: int
    packet_index: int
    payload_length: int
    sync_time: int
    timestamp: int
    mode: int
    start_channel: int
    included_channels: int
    start_signal: int
    included_signals: int
    buffer_id: int
    payload_offset: int

    @property
    def floating_point(self) -> bool:
        """Whether the payload holds float64 values (mode bit 7)."""
        return bool(self.mode & MODE_FLOATING_POINT)

    @property
    def time_s(self) -> float:
        """Unix time of the spectrum: ``sync_time + timestamp * 32768 * 2.5 ns``."""
        return self.sync_time + self.timestamp * TIMESTAMP_UNIT_S


@dataclass(frozen=True, slots=True)
class SpeadPacket:
    """One decoded datagram: its header and a view of its data bytes (no copy)."""

    header: SpeadHeader
    payload: memoryview

    def values(self) -> np.ndarray:
        """The payload as float64 (floating-point mode) or int64 values, little-endian."""
        dtype = "<f8" if self.header.floating_point else "<i8"
        return np.frombuffer(self.payload, dtype=dtype)


def _bad(message: str) -> ProtocolError:
    return ProtocolError("itpm", message, "spead decode")


def parse_header(buffer: bytes | bytearray | memoryview, nbytes: int) -> tuple[int, ...]:
    """Validate the first ``nbytes`` of ``buffer`` as a packet and return its item values.

    The fast path of the receiver: one ``struct`` unpack of the 72 header bytes, one
    tuple comparison of the item ids, no objects made per item.

    Returns
    -------
    tuple of int
        The 48-bit values in :data:`ITEM_ORDER` order: heap counter, payload length,
        sync time, timestamp, mode, channel info, buffer id, payload offset.

    Raises
    ------
    ProtocolError
        Short datagram, wrong magic/version/widths/item count, unknown or missing items,
        a payload length that is not the datagram's, a bad payload offset.
    """
    if nbytes < HEADER_BYTES:
        raise _bad(f"datagram of {nbytes} bytes is shorter than the {HEADER_BYTES}-byte header")
    words = _WORDS.unpack_from(buffer)
    if words[0] != HEADER_WORD:
        raise _bad(_describe_header_word(words[0]))
    if _IDS.unpack_from(buffer) == WIRE_IDS:
        _, heap, length, sync, stamp, mode, info, buffer_id, offset = words
        m = VALUE_MASK
        values: tuple[int, ...] = (
            heap & m,
            length & m,
            sync & m,
            stamp & m,
            mode & m,
            info & m,
            buffer_id & m,
            offset & m,
        )
    else:
        values = _values_by_id(words[1:])
    length, offset = values[1], values[7]
    if length != nbytes - HEADER_BYTES:
        raise _bad(f"payload length item says {length} bytes, datagram carries {nbytes - 72}")
    if offset > length or (length - offset) % VALUE_BYTES:
        raise _bad(f"payload offset {offset} does not fit a {length}-byte payload")
    return values


def _describe_header_word(word: int) -> str:
    fields = (word >> 56, (word >> 48) & 0xFF, (word >> 40) & 0xFF, (word >> 32) & 0xFF)
    expected = (MAGIC, VERSION, ITEM_POINTER_WIDTH, HEAP_ADDRESS_WIDTH)
    names = ("magic", "version", "item-pointer width", "heap-address width")
    for name, got, want in zip(names, fields, expected, strict=True):
        if got != want:
            return f"SPEAD {name} is {got:#x}, expected {want:#x}"
    if word & 0xFFFF != N_ITEMS:
        return f"packet has {word & 0xFFFF} items, expected {N_ITEMS}"
    return f"unexpected SPEAD header word {word:#018x}"


def _values_by_id(items: tuple[int, ...]) -> tuple[int, ...]:
    """Slow path: items in another order, or the 0x2003 buffer id reach_control accepts."""
    found: dict[int, int] = {}
    for word in items:
        item_id = (word >> 48) & 0x7FFF
        if item_id == BUFFER_ID_ALT:
            item_id = BUFFER_ID
        expected_flag = 0 if item_id == PAYLOAD_OFFSET else 1
        if item_id not in ITEM_ORDER or word >> 63 != expected_flag or item_id in found:
            raise _bad(f"unexpected SPEAD item {word >> 48:#06x}")
        found[item_id] = word & VALUE_MASK
    return tuple(found[i] for i in ITEM_ORDER)


def decode_packet(
    datagram: bytes | bytearray | memoryview, nbytes: int | None = None
) -> SpeadPacket:
    """Decode one datagram (its first ``nbytes`` bytes) into header and payload view.

    Raises
    ------
    ProtocolError
        As :func:`parse_header`.
    """
    size = len(datagram) if nbytes is None else nbytes
    heap, length, sync, timestamp, mode, info, buffer_id, offset = parse_header(datagram, size)
    header = SpeadHeader(
        heap_counter=heap & 0xFFFFFF,
        packet_index=(heap >> 24) & 0xFFFF,
        payload_length=length,
        sync_time=sync,
        timestamp=timestamp,
        mode=mode,
        start_channel=(info >> 24) & 0xFFFF,
        included_channels=(info >> 16) & 0xFF,
        start_signal=(info >> 8) & 0xFF,
        included_signals=info & 0xFF,
        buffer_id=(buffer_id & 0xFFFFFFFF) >> 16,
        payload_offset=offset,
    )
    view = memoryview(datagram)[HEADER_BYTES + offset : HEADER_BYTES + length]
    return SpeadPacket(header, view)


def signals_per_fpga(n_inputs: int) -> int:
    """Signals each of the iTPM's two FPGAs carries: ``n_inputs // 2`` (reach_control)."""
    if n_inputs < 2 or n_inputs % 2:
        raise ValueError(f"the iTPM spectrometer has an even number >= 2 of inputs, not {n_inputs}")
    return n_inputs // 2


def bit_reverse(indices: np.ndarray, n_bits: int) -> np.ndarray:
    """Reverse the lowest ``n_bits`` bits of each index (vectorised)."""
    result = np.zeros_like(indices)
    work = indices.copy()
    for _ in range(n_bits):
        result = (result << 1) | (work & 1)
        work >>= 1
    return result


def physical_index(n_inputs: int, n_channels: int, floating_point: bool = True) -> np.ndarray:
    """Physical (input, channel) flat index of each value slot of the assembled heap.

    The heap buffer is the reach_control "reassembled" array, (2, s x n_channels) with
    ``s = n_inputs // 2``, flattened; a packet with start signal ``g`` and start channel
    ``c`` fills row ``g // s`` from column ``c x s``. Slot ``w`` holds the value of
    physical flat index ``input x n_channels + channel = physical_index(...)[w]``, so
    ``physical.flat[index] = heap`` and ``heap = physical.flat[index]``.

    Raises
    ------
    ValueError
        A channel count that is not a power of two in floating-point mode (bit reversal
        needs one) or odd with more than one signal per FPGA.
    """
    per_fpga = signals_per_fpga(n_inputs)
    n_bits = int(n_channels).bit_length() - 1
    if floating_point and n_channels != 1 << n_bits:
        raise ValueError(f"bit reversal needs a power-of-two channel count, not {n_channels}")
    if per_fpga != 1 and n_channels % 2:
        raise ValueError(f"the even/odd descramble needs an even channel count, not {n_channels}")
    slots = np.arange(n_inputs * n_channels, dtype=np.int64)
    row, column = np.divmod(slots, per_fpga * n_channels)
    signal = per_fpga * row + column % per_fpga
    channel = column // per_fpga
    if per_fpga != 1:
        channel = np.where(channel % 2 == 0, channel // 2, channel // 2 + n_channels // 2)
    if floating_point:
        channel = bit_reverse(channel, n_bits)
    return signal * n_channels + channel


def heap_gather_index(n_inputs: int, n_channels: int, floating_point: bool = True) -> np.ndarray:
    """Inverse of :func:`physical_index`: ``physical.flat = heap[gather]``."""
    return np.argsort(physical_index(n_inputs, n_channels, floating_point)).astype(np.intp)
