"""``skinkit robot emulate``: contributed to the core CLI through ``skinkit.commands.robot``."""

from __future__ import annotations

import click


@click.command("emulate")
@click.option(
    "--serial", "link", flag_value="serial", default=True, help="serve the serial protocol on a pty"
)
@click.option("--can", "link", flag_value="can", help="serve the CAN protocol over the loopback bridge")
@click.option("--baud", type=int, default=921600, show_default=True, help="serial link speed (0: unlimited)")
@click.option("--bitrate", type=int, default=1_000_000, show_default=True, help="CAN bit rate (0: unlimited)")
@click.option("--port", type=int, default=0, help="CAN bridge TCP port on 127.0.0.1 (0: any free)")
@click.option(
    "--speed", type=float, default=1.0, show_default=True, help="real-time factor (0: as fast as drained)"
)
@click.option("--skin", default="kelvin-voigt", show_default=True, help="kelvin-voigt, wiener, none, spring")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--buffer-bytes", type=int, default=65536, show_default=True, help="device transmit buffer")
def emulate(
    link: str, baud: int, bitrate: int, port: int, speed: float, skin: str, seed: int, buffer_bytes: int
) -> None:
    """Run the robot emulator; prints the port it serves, then serves until interrupted."""
    from skinkit_hardware.emulator import main

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
