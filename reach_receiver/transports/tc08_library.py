"""The Pico TC-08's C library (``libusbtc08``) through ctypes, and the TC-08 on USB.

No open wire protocol exists for the TC-08 (USB ``0ce9:1000``): every known driver
calls Pico Technology's ``libusbtc08`` (``libusbtc08.so`` on Linux, from Pico's
``libusbtc08`` package; ``usbtc08.dll`` on Windows). :class:`Tc08Library` is the handful
of its functions the driver uses, with Python signatures that mirror the C ones, so the
real binding (:func:`load_libusbtc08`) and a stand-in are interchangeable.

C API, as declared in Pico's ``usbtc08.h`` and its ``picosdk-python-wrappers``
(``picosdk/usbtc08.py``), checked for this module::

    int16_t usb_tc08_open_unit(void);
    int16_t usb_tc08_close_unit(int16_t handle);
    int16_t usb_tc08_set_mains(int16_t handle, int16_t sixty_hertz);
    int16_t usb_tc08_set_channel(int16_t handle, int16_t channel, int8_t tc_type);
    int16_t usb_tc08_get_single(int16_t handle, float *temp, int16_t *overflow_flags,
                                int16_t units);
    int16_t usb_tc08_get_last_error(int16_t handle);
    int16_t usb_tc08_get_unit_info2(int16_t handle, int8_t *string, int16_t string_length,
                                    int16_t line);

``temp`` has 9 floats, index 0 the cold junction; ``units`` is one of
:data:`USBTC08_UNITS_CENTIGRADE` (0), FAHRENHEIT (1), KELVIN (2), RANKINE (3);
``tc_type`` an ASCII letter (B E J K N R S T, X for millivolts, space to disable);
``sixty_hertz`` 0 for a 50 Hz mains filter, 1 for 60 Hz. Error codes 0-14 of
:data:`TC08_ERRORS` agree across Pico's header and wrappers; code 15 differs between
header versions, 16 is COMMUNICATION in the newer one.

From Pico's programmer's guide, not re-checked here: ``open_unit`` returns a handle
> 0, 0 when no (further) unit is found and -1 on error (then
``get_last_error(0)`` says why); the other calls return 0 on failure, and
``get_single`` sets bit ``n`` of ``overflow_flags`` when channel ``n`` is over range.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass
from typing import Protocol, TypeAlias

import usb.core
import usb.util

from reach_receiver.errors import DeviceError

#: USB vendor and product ids of the TC-08.
TC08_VENDOR_ID = 0x0CE9
TC08_PRODUCT_ID = 0x1000
#: Temperature units of ``usb_tc08_get_single``.
USBTC08_UNITS_CENTIGRADE, USBTC08_UNITS_FAHRENHEIT = 0, 1
USBTC08_UNITS_KELVIN, USBTC08_UNITS_RANKINE = 2, 3
#: Channels: 0 is the cold junction, 1-8 thermocouples.
USBTC08_CHANNEL_CJC = 0
USBTC08_MAX_CHANNELS = 8
#: ``usb_tc08_get_unit_info2`` line that holds the batch and serial number.
USBTC08LINE_BATCH_AND_SERIAL = 4
#: Error codes of ``usb_tc08_get_last_error``: (name, meaning).
TC08_ERRORS: dict[int, tuple[str, str]] = {
    0: ("USBTC08_ERROR_OK", "no error"),
    1: ("USBTC08_ERROR_OS_NOT_SUPPORTED", "the driver does not support this operating system"),
    2: ("USBTC08_ERROR_NO_CHANNELS_SET", "no channel has been set up"),
    3: ("USBTC08_ERROR_INVALID_PARAMETER", "an argument was invalid"),
    4: ("USBTC08_ERROR_VARIANT_NOT_SUPPORTED", "hardware version not supported by the driver"),
    5: ("USBTC08_ERROR_INCORRECT_MODE", "legacy and new calls mixed, or read while streaming"),
    6: ("USBTC08_ERROR_ENUMERATION_INCOMPLETE", "a background enumeration is still running"),
    7: ("USBTC08_ERROR_NOT_RESPONDING", "the unit does not reply"),
    8: ("USBTC08_ERROR_FW_FAIL", "firmware download failed"),
    9: ("USBTC08_ERROR_CONFIG_FAIL", "EEPROM missing or corrupted"),
    10: ("USBTC08_ERROR_NOT_FOUND", "cannot find the enumerated unit"),
    11: ("USBTC08_ERROR_THREAD_FAIL", "a threading call failed"),
    12: ("USBTC08_ERROR_PIPE_INFO_FAIL", "cannot read the USB pipe information"),
    13: ("USBTC08_ERROR_NOT_CALIBRATED", "no calibration date: the unit is not calibrated"),
    14: ("USBTC08_ERROR_PICOPP_TOO_OLD", "the picopp driver is too old"),
    15: ("USBTC08_ERROR_15", "PICO_DRIVER_FUNCTION or COMMUNICATION, by header version"),
    16: ("USBTC08_ERROR_COMMUNICATION", "communication with the unit failed"),
}
#: Where Pico's Linux package installs the library when the loader does not know it.
_LINUX_CANDIDATES = ("libusbtc08.so", "libusbtc08.so.2", "/opt/picoscope/lib/libusbtc08.so")

FloatArray: TypeAlias = "ctypes.Array[ctypes.c_float]"
Int16Array: TypeAlias = "ctypes.Array[ctypes.c_int16]"
CharArray: TypeAlias = "ctypes.Array[ctypes.c_char]"


def describe_error(code: int) -> str:
    """``NAME (meaning)`` of a ``usb_tc08_get_last_error`` code."""
    name, meaning = TC08_ERRORS.get(code, (f"error {code}", "unknown error code"))
    return f"{name} ({meaning})"


class Tc08Library(Protocol):
    """The C functions the driver calls, with the C calling convention.

    Output arguments are ctypes buffers that the function fills: ``temp`` a
    ``(c_float * 9)`` array, ``overflow_flags`` a ``(c_int16 * 1)`` array (a valid
    ``int16_t *``), ``string`` a ``create_string_buffer``. Return values are the C ones.
    """

    def usb_tc08_open_unit(self) -> int:
        """Open the next unit: handle > 0, 0 if none is left, -1 on error."""
        ...

    def usb_tc08_close_unit(self, handle: int) -> int:
        """Close a unit: 1 on success, 0 on error."""
        ...

    def usb_tc08_set_mains(self, handle: int, sixty_hertz: int) -> int:
        """Select the 50 Hz (0) or 60 Hz (1) rejection filter: 1 on success."""
        ...

    def usb_tc08_set_channel(self, handle: int, channel: int, tc_type: int) -> int:
        """Set channel 0-8 to thermocouple type ``ord(letter)``: 1 on success."""
        ...

    def usb_tc08_get_single(
        self, handle: int, temp: FloatArray, overflow_flags: Int16Array, units: int
    ) -> int:
        """Convert every enabled channel once into ``temp``: 1 on success, 0 on error."""
        ...

    def usb_tc08_get_last_error(self, handle: int) -> int:
        """The last error of ``handle`` (0 for errors of ``open_unit``)."""
        ...

    def usb_tc08_get_unit_info2(
        self, handle: int, string: CharArray, string_length: int, line: int
    ) -> int:
        """Copy one line of unit information into ``string``: its length, 0 on error."""
        ...


class _LoadedTc08:
    """The real ``libusbtc08`` behind :class:`Tc08Library`."""

    def __init__(self, cdll: ctypes.CDLL) -> None:
        i16 = ctypes.c_int16
        f_p, i16_p = ctypes.POINTER(ctypes.c_float), ctypes.POINTER(ctypes.c_int16)
        signatures: dict[str, list[type]] = {
            "usb_tc08_open_unit": [],
            "usb_tc08_close_unit": [i16],
            "usb_tc08_set_mains": [i16, i16],
            "usb_tc08_set_channel": [i16, i16, ctypes.c_int8],
            "usb_tc08_get_single": [i16, f_p, i16_p, i16],
            "usb_tc08_get_last_error": [i16],
            # int8_t* in C; char* is the same pointer and takes a create_string_buffer
            "usb_tc08_get_unit_info2": [i16, ctypes.c_char_p, i16, i16],
        }
        for name, argtypes in signatures.items():
            function = getattr(cdll, name)
            function.argtypes = argtypes
            function.restype = i16
        self._lib = cdll

    def usb_tc08_open_unit(self) -> int:
        return int(self._lib.usb_tc08_open_unit())

    def usb_tc08_close_unit(self, handle: int) -> int:
        return int(self._lib.usb_tc08_close_unit(handle))

    def usb_tc08_set_mains(self, handle: int, sixty_hertz: int) -> int:
        return int(self._lib.usb_tc08_set_mains(handle, sixty_hertz))

    def usb_tc08_set_channel(self, handle: int, channel: int, tc_type: int) -> int:
        return int(self._lib.usb_tc08_set_channel(handle, channel, tc_type))

    def usb_tc08_get_single(
        self, handle: int, temp: FloatArray, overflow_flags: Int16Array, units: int
    ) -> int:
        return int(self._lib.usb_tc08_get_single(handle, temp, overflow_flags, units))

    def usb_tc08_get_last_error(self, handle: int) -> int:
        return int(self._lib.usb_tc08_get_last_error(handle))

    def usb_tc08_get_unit_info2(
        self, handle: int, string: CharArray, string_length: int, line: int
    ) -> int:
        return int(self._lib.usb_tc08_get_unit_info2(handle, string, string_length, line))


def load_libusbtc08(path: str | None = None) -> Tc08Library:
    """Load Pico's ``libusbtc08`` and declare the argument and return types.

    Parameters
    ----------
    path
        The shared library; by default the dynamic loader's ``usbtc08``, then
        ``/opt/picoscope/lib/libusbtc08.so``.

    Raises
    ------
    DeviceError
        If the library cannot be loaded or lacks one of the functions.
    """
    found = ctypes.util.find_library("usbtc08")
    candidates = [path] if path else [c for c in (found, *_LINUX_CANDIDATES) if c]
    problems = []
    for candidate in candidates:
        try:
            cdll = ctypes.CDLL(candidate)
        except OSError as err:
            problems.append(f"{candidate}: {err}")
            continue
        try:
            return _LoadedTc08(cdll)
        except AttributeError as err:
            message = f"{candidate} is not a usable libusbtc08: {err}"
            raise DeviceError("tc08", message, "load") from err
    message = (
        "cannot load Pico Technology's libusbtc08 (install Pico's 'libusbtc08' package, "
        "https://www.picotech.com/downloads/linux); tried " + "; ".join(problems)
    )
    raise DeviceError("tc08", message, "load")


@dataclass(frozen=True)
class UsbDeviceInfo:
    """Where a TC-08 sits on the USB: bus, address and (if readable) serial string."""

    bus: int
    address: int
    serial: str | None


def find_tc08_devices() -> list[UsbDeviceInfo]:
    """TC-08s (``0ce9:1000``) on the USB, through pyusb; empty without a libusb backend."""
    try:
        devices = list(
            usb.core.find(find_all=True, idVendor=TC08_VENDOR_ID, idProduct=TC08_PRODUCT_ID)
        )
    except usb.core.NoBackendError:
        return []
    found = []
    for device in devices:
        serial = None
        try:
            if device.iSerialNumber:
                serial = usb.util.get_string(device, device.iSerialNumber)
        except (usb.core.USBError, ValueError, NotImplementedError):
            serial = None  # reading strings needs permission on the device node
        found.append(UsbDeviceInfo(bus=device.bus, address=device.address, serial=serial))
    return found


def reset_tc08(bus: int, address: int) -> None:
    """Reset (re-enumerate) the TC-08 at ``bus``/``address`` through pyusb.

    Raises
    ------
    DeviceError
        If there is no libusb backend, no TC-08 at that place, or the reset fails.
    """
    command = f"reset {bus}:{address}"
    try:
        device = usb.core.find(
            idVendor=TC08_VENDOR_ID,
            idProduct=TC08_PRODUCT_ID,
            custom_match=lambda d: d.bus == bus and d.address == address,
        )
    except usb.core.NoBackendError as err:
        raise DeviceError("tc08", "no libusb backend for pyusb", command) from err
    if device is None:
        raise DeviceError("tc08", f"no TC-08 at bus {bus} address {address}", command)
    try:
        device.reset()
    except usb.core.USBError as err:
        raise DeviceError("tc08", f"USB reset failed: {err}", command) from err
