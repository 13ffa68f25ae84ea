"""``skinkit robot emulate``: contributed to the core CLI through ``skinkit.commands.robot``."""

from __future__ import annotations

import click

from skinkit.plugin.commands import FiniteFloat


@click.command("emulate")
@click.option(
    "--serial", "link", flag_value="serial", default=True, help="serve the serial protocol on a pty"
)
@click.option("--can", "link", flag_value="can", help="serve the CAN protocol over the loopback bridge")
@click.option("--baud", type=click.IntRange(0, 12_000_000), default=921600, show_default=True,
              help="serial link speed (0: unlimited)")
@click.option("--bitrate", type=click.IntRange(0, 8_000_000), default=1_000_000, show_default=True,
              help="CAN bit rate (0: unlimited)")
@click.option("--port", type=click.IntRange(0, 65535), default=0,
              help="CAN bridge TCP port on 127.0.0.1 (0: any free)")
@click.option("--speed", type=FiniteFloat(0.0, 1000.0), default=1.0, show_default=True,
              help="real-time factor (0: as fast as drained)")
@click.option("--skin", type=click.Choice(["kelvin-voigt", "wiener", "none", "spring"]),
              default="kelvin-voigt", show_default=True, help="skin load behind the tip")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True)
@click.option("--buffer-bytes", type=click.IntRange(64, 2**30), default=65536, show_default=True,
              help="device transmit buffer [bytes]")
def emulate(
    link: str, baud: int, bitrate: int, port: int, speed: float, skin: str, seed: int, buffer_bytes: int
) -> None:
    """Run the robot emulator; prints the port it serves, then serves until interrupted."""
    import errno

    from skinkit.errors import SkinkitError
    from skinkit_hardware.emulator import main

    if link == "can" and port:
        _check_port_free(port)  # before the emulator starts its bus
    try:
        _serve(main, link, baud, bitrate, port, speed, skin, seed, buffer_bytes)
    except OSError as exc:
        if exc.errno in (errno.EADDRINUSE, errno.EACCES, errno.EADDRNOTAVAIL):
            raise SkinkitError(f"--port {port}: cannot listen on 127.0.0.1:{port} ({exc.strerror})") from None
        raise


def _check_port_free(port: int) -> None:
    import socket

    from skinkit.errors import SkinkitError

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError as exc:
            raise SkinkitError(f"--port {port}: cannot listen on 127.0.0.1:{port} ({exc.strerror})") from None


def _serve(main, link: str, baud: int, bitrate: int, port: int, speed: float, skin: str, seed: int,
           buffer_bytes: int) -> None:
    main(
        [
            link,
            "--baud",
            str(baud),
            "--bitrate",
            str(bitrate),
            "--port",
            str(port),
            "--speed",
            str(speed),
            "--skin",
            skin,
            "--seed",
            str(seed),
            "--buffer-bytes",
            str(buffer_bytes),
        ]
    )
