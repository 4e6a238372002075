"""Links from the control PC to the servo nodes: serial (pyserial) or CAN
(python-can), both speaking firmware_protocol/SPEC.md.

    open_link("serial:/dev/ttyUSB0@1000000")     # device, baud rate
    open_link("serial:socket://10.0.0.5:7000")   # any pyserial URL
    open_link("can:socketcan:can0")              # interface, channel
    open_link("can:slcan:/dev/ttyACM0@500000")   # ... and CAN bit rate
"""
from __future__ import annotations

from marionette.errors import MarionetteError


class LinkError(MarionetteError):
    """A link could not be opened or its description is wrong."""


def open_link(spec: str):
    """A SerialLink or CanLink from 'serial:URL[@BAUD]' or 'can:INTERFACE:CHANNEL[@BITRATE]'."""
    kind, _, rest = spec.partition(":")
    target, rate = rest, None
    if "@" in rest and not rest.startswith(("socket://", "rfc2217://")):
        target, _, rate_text = rest.rpartition("@")
        try:
            rate = int(rate_text)
        except ValueError:
            raise LinkError(f"link {spec!r}: rate {rate_text!r} is not a whole number") from None
    try:
        if kind == "serial" and target:
            from marionette.transport.serial_link import DEFAULT_BAUDRATE, SerialLink
            return SerialLink(target, rate or DEFAULT_BAUDRATE)
        if kind == "can":
            interface, _, channel = target.partition(":")
            if interface and channel:
                from marionette.transport.can_link import CanLink
                kwargs = {"interface": interface, "channel": channel}
                if rate:
                    kwargs["bitrate"] = rate
                return CanLink(**kwargs)
    except OSError as exc:
        raise LinkError(str(exc)) from None
    raise LinkError(f"link {spec!r}: expected 'serial:URL[@BAUD]' or "
                    f"'can:INTERFACE:CHANNEL[@BITRATE]'")
