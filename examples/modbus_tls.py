"""Modbus/TCP Security: mutual TLS, and what each client may do decided by its role.

The server (``aiortu.serve("tls://host:802", ...)``) accepts clients whose certificate its CA
signed, reads each client's role from the certificate (extension 1.3.6.1.4.1.50316.802.1), and
answers a request the role's rule does not allow with exception 01. Here a CA, the server's
certificate and two clients' (an operator and a viewer) are made in a temporary directory with
the ``cryptography`` package (``pip install cryptography``; docs/security.md shows the same
with ``openssl``). Run it on its own::

    python examples/modbus_tls.py
"""

from __future__ import annotations

import datetime
import ipaddress
import tempfile
from pathlib import Path

import anyio
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

import aiortu
from aiortu.transport import ROLE_OID, AccessRule, RoleRules

Issued = tuple[x509.Certificate, ec.EllipticCurvePrivateKey]


def issue(
    folder: Path, name: str, ca: Issued | None, extensions: list[x509.ExtensionType]
) -> Issued:
    """A certificate for `name` signed by `ca` (self-signed when None), written to `folder`."""
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(ca[0].subject if ca else subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
    )
    for extension in extensions:
        builder = builder.add_extension(extension, critical=False)
    certificate = builder.sign(ca[1] if ca else key, hashes.SHA256())
    (folder / f"{name}.crt").write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    (folder / f"{name}.key").write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return certificate, key


def role(name: str) -> x509.UnrecognizedExtension:
    """The role extension: the name as a DER UTF8String."""
    return x509.UnrecognizedExtension(
        x509.ObjectIdentifier(ROLE_OID), bytes((0x0C, len(name))) + name.encode()
    )


async def main(folder: Path) -> None:
    ca = issue(folder, "ca", None, [x509.BasicConstraints(ca=True, path_length=None)])
    local = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
    issue(folder, "server", ca, [x509.SubjectAlternativeName(local)])
    issue(folder, "operator", ca, [role("operator")])
    issue(folder, "viewer", ca, [role("viewer")])
    rules = RoleRules(
        {
            "operator": AccessRule(frozenset({3, 6, 16})),
            "viewer": AccessRule(frozenset({3}), read_only=True),
        }
    )
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]})
    files = {"certfile": folder / "server.crt", "keyfile": folder / "server.key"}
    async with aiortu.serve(
        "tls://127.0.0.1:0", {1: store}, cafile=folder / "ca.crt", rules=rules, **files
    ) as server:
        for who in ("operator", "viewer"):
            async with aiortu.open_master(
                f"tls://127.0.0.1:{server.port}",
                certfile=folder / f"{who}.crt",
                keyfile=folder / f"{who}.key",
                cafile=folder / "ca.crt",
            ) as master:
                try:
                    await master.write_register(1, 0, 230 if who == "operator" else 0)
                    print(f"{who}: setpoint written")
                except aiortu.ExceptionResponse as refused:
                    print(f"{who}: write refused with exception {refused.code:02X}")
                print(f"{who}: setpoint = {(await master.read_holding_registers(1, 0, 1))[0]}")
        print(f"requests denied by the rules: {server.denied}")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as directory:
        anyio.run(main, Path(directory))
