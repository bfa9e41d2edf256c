"""`supportnode keys DIR [--name NAME]`: make a ZeroMQ CURVE key pair for secured sockets.

Writes ``DIR/NAME.key`` (public key: give it to peers) and ``DIR/NAME.key_secret`` (public and
secret key: keep it private) with `zmq.auth.create_certificates`, then prints where they go.
"""

from __future__ import annotations

import argparse
import os

from supportnode.errors import SupportNodeError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", help="folder to write the key files into (created if missing)")
    parser.add_argument(
        "--name",
        default="server",
        help="base name of the key files (default server: what the node loads)",
    )
    parser.add_argument(
        "--force", action="store_true", help="overwrite existing key files of that name"
    )


def run(args: argparse.Namespace) -> int:
    import zmq
    import zmq.auth

    if not zmq.has("curve"):
        raise SupportNodeError("this libzmq was built without CURVE support")
    name = args.name
    if not name or os.sep in name or name.startswith("."):
        raise SupportNodeError(f"--name {name!r}: expected a plain file name without a folder")
    public = os.path.join(args.dir, f"{name}.key")
    secret = os.path.join(args.dir, f"{name}.key_secret")
    if not args.force:
        for path in (public, secret):
            if os.path.exists(path):
                raise SupportNodeError(f"{path}: exists (use --force to overwrite)")
    try:
        os.makedirs(args.dir, exist_ok=True)
        public, secret = zmq.auth.create_certificates(args.dir, name)
        os.chmod(secret, 0o600)
    except OSError as err:
        raise SupportNodeError(f"{args.dir}: cannot write key files ({err.strerror})") from err
    print(f"public key: {public}")
    print(f"secret key: {secret}  (keep private; mode 600)")
    print("Where to copy them (the node's folder layout: see supportnode.curve):")
    print(
        f"  - the socket that BINDS (server) uses {name}.key_secret; for the node: "
        "node.curve_keys_dir/server.key_secret"
    )
    print(
        f"  - a server that should accept this key as a client: copy {name}.key into its "
        "authorised folder (for the node: node.curve_keys_dir/subscribers/ to subscribe to "
        "results, node.curve_keys_dir/drivers/ to publish scans to a node that binds)"
    )
    print(
        f"  - a client connecting to this key's server: {name}.key is its server key "
        "(for a node connecting to a scan driver: node.curve_keys_dir/scan_server.key; for "
        "echo, hz, record, view: --curve-server-key)"
    )
    return 0
