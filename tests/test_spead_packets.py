"""SPEAD packet decoding against datagrams built by hand from the layout.

The packets here are packed field by field with ``struct`` from the layout in
``lessju/reach_control`` ``spectra.py`` and SKA ``ska-low-mccs-daq`` ``SPEAD.h``; they do not
use the simulator's encoder, so an error shared by encoder and decoder would show.
"""

import struct

import numpy as np
import pytest

from reach_receiver.devices import spead
from reach_receiver.errors import ProtocolError

SYNC = 1_700_000_000
N_CHANNELS = 16384


def item(wire_id: int, value: int) -> bytes:
    """One item word: 16 bits of flag + id, 48 bits of value, big-endian."""
    return struct.pack(">HHI", wire_id, value >> 32, value & 0xFFFFFFFF)


def build_packet(
    *,
    timestamp=12345,
    start_channel=0,
    start_signal=0,
    heap_counter=7,
    packet_index=0,
    mode=0x86,
    payload=None,
    payload_length=None,
    offset=0,
    header=None,
    items=None,
) -> bytes:
    if payload is None:
        payload = struct.pack("<128d", *range(128))
    if header is None:
        # magic 0x53, version 4, item-pointer width 2, heap-address width 6, 8 items
        header = struct.pack(">BBBBHH", 0x53, 4, 2, 6, 0, 8)
    if items is None:
        items = [
            item(0x8001, (packet_index << 24) | heap_counter),
            item(0x8004, len(payload) if payload_length is None else payload_length),
            item(0x9027, SYNC),
            item(0x9600, timestamp),
            item(0xA004, mode),
            item(0xA002, (start_channel << 24) | (128 << 16) | (start_signal << 8) | 1),
            item(0xA001, 0x0003_0000),
            item(0x3300, offset),
        ]
    return header + b"".join(items) + payload


def test_items_are_parsed():
    values = np.arange(128, dtype="<f8") * 0.5
    packet = build_packet(
        timestamp=0xABCDEF012,
        start_channel=256,
        start_signal=1,
        heap_counter=0x123456,
        packet_index=130,
        payload=values.tobytes(),
    )
    assert len(packet) == 1096
    decoded = spead.decode_packet(packet)
    h = decoded.header
    assert h.heap_counter == 0x123456
    assert h.packet_index == 130
    assert h.payload_length == 1024
    assert h.sync_time == SYNC
    assert h.timestamp == 0xABCDEF012
    assert h.mode == 0x86
    assert h.floating_point
    assert h.start_channel == 256
    assert h.included_channels == 128
    assert h.start_signal == 1
    assert h.included_signals == 1
    assert h.buffer_id == 3
    assert h.payload_offset == 0
    assert h.time_s == pytest.approx(SYNC + 0xABCDEF012 * 32768 * 2.5e-9, abs=1e-6)
    np.testing.assert_array_equal(decoded.values(), values)


def test_integer_mode_payload_is_int64():
    values = np.arange(-64, 64, dtype="<i8") * 1000
    decoded = spead.decode_packet(build_packet(mode=0x06, payload=values.tobytes()))
    assert not decoded.header.floating_point
    assert decoded.values().dtype == np.int64
    np.testing.assert_array_equal(decoded.values(), values)


def test_items_in_another_order_and_alternate_buffer_id():
    items = [
        item(0x9600, 99),
        item(0x8001, 5),
        item(0x3300, 0),
        item(0x8004, 1024),
        item(0xA003, 0x0002_0000),  # reach_control accepts 0x2003 for the buffer id
        item(0xA002, 128 << 24),
        item(0x9027, SYNC),
        item(0xA004, 0x80),
    ]
    h = spead.decode_packet(build_packet(items=items)).header
    assert (h.timestamp, h.heap_counter, h.start_channel, h.buffer_id) == (99, 5, 128, 2)


def test_payload_offset_skips_bytes():
    payload = b"\xff" * 8 + struct.pack("<127d", *range(127))
    decoded = spead.decode_packet(build_packet(payload=payload, offset=8))
    np.testing.assert_array_equal(decoded.values(), np.arange(127.0))


@pytest.mark.parametrize(
    ("header", "message"),
    [
        (struct.pack(">BBBBHH", 0x54, 4, 2, 6, 0, 8), "magic"),
        (struct.pack(">BBBBHH", 0x53, 3, 2, 6, 0, 8), "version"),
        (struct.pack(">BBBBHH", 0x53, 4, 3, 6, 0, 8), "item-pointer width"),
        (struct.pack(">BBBBHH", 0x53, 4, 2, 5, 0, 8), "heap-address width"),
        (struct.pack(">BBBBHH", 0x53, 4, 2, 6, 0, 7), "items"),
    ],
)
def test_bad_header_word(header, message):
    with pytest.raises(ProtocolError, match=message):
        spead.decode_packet(build_packet(header=header))


@pytest.mark.parametrize("size", [0, 1, 8, 71])
def test_short_datagram(size):
    with pytest.raises(ProtocolError, match="shorter"):
        spead.decode_packet(build_packet()[:size])


def test_truncated_payload_fails_length_check():
    with pytest.raises(ProtocolError, match="payload length"):
        spead.decode_packet(build_packet()[:-8])


def test_wrong_payload_length_item():
    with pytest.raises(ProtocolError, match="payload length"):
        spead.decode_packet(build_packet(payload_length=1016))


def test_unknown_item_and_bad_offset():
    items = [item(0x8001, 0)] + [item(0x8005, 0)] * 7
    with pytest.raises(ProtocolError, match="item"):
        spead.decode_packet(build_packet(items=items))
    with pytest.raises(ProtocolError, match="offset"):
        spead.decode_packet(build_packet(offset=4))


def test_nbytes_limits_the_datagram_in_a_larger_buffer():
    packet = build_packet(timestamp=42)
    buffer = bytearray(2000)
    buffer[: len(packet)] = packet
    assert spead.decode_packet(buffer, len(packet)).header.timestamp == 42
    with pytest.raises(ProtocolError):
        spead.decode_packet(buffer, len(packet) + 1)


def reverse14(n: int) -> int:
    return int(format(n, "014b")[::-1], 2)


def test_bit_reversal_matches_the_string_definition():
    n = np.arange(N_CHANNELS)
    expected = np.array([reverse14(k) for k in range(N_CHANNELS)])
    np.testing.assert_array_equal(spead.bit_reverse(n, 14), expected)


def test_float_mode_channel_order_from_hand_built_packets():
    """Values encoding their physical index, placed as the firmware places them."""
    # Firmware order (reach_control, 2 inputs = 1 signal per FPGA): heap slot n of input
    # g holds physical channel reverse14(n); packet k of input g starts at slot 128 k.
    packets = []
    for signal in range(2):
        for k in range(128):
            slots = range(128 * k, 128 * (k + 1))
            values = [signal * 100_000 + reverse14(n) for n in slots]
            payload = struct.pack("<128d", *values)
            packet = build_packet(start_channel=128 * k, start_signal=signal, payload=payload)
            packets.append(packet)
    heap = np.empty(2 * N_CHANNELS)
    for packet in packets:
        h = spead.decode_packet(packet)
        row = h.header.start_signal
        start = row * N_CHANNELS + h.header.start_channel
        heap[start : start + 128] = h.values()
    physical = heap[spead.heap_gather_index(2, N_CHANNELS)].reshape(2, N_CHANNELS)
    expected = np.arange(N_CHANNELS) + 100_000 * np.arange(2)[:, None]
    np.testing.assert_array_equal(physical, expected)


def test_four_signal_order_demultiplexes_and_descrambles():
    """reach_control's 4-signal path: signal interleave, then even/odd, then bit reversal."""
    n = 16
    index = spead.physical_index(4, n, floating_point=True)
    # row 0, column 5 -> signal 1, position 2 -> even -> channel 1 -> reversed (4 bits) 8
    assert index[5] == 1 * n + 8
    # row 1, column 7 -> signal 3, position 3 -> odd -> channel 1 + 8 = 9 -> reversed 9
    assert index[2 * n + 7] == 3 * n + 9
    assert sorted(index) == list(range(4 * n))
    integer = spead.physical_index(4, n, floating_point=False)
    assert integer[2 * n + 7] == 3 * n + 9
    assert integer[5] == 1 * n + 1


def test_order_map_rejects_bad_shapes():
    with pytest.raises(ValueError, match="power-of-two"):
        spead.physical_index(2, 1000)
    with pytest.raises(ValueError, match="even"):
        spead.physical_index(3, 1024)
