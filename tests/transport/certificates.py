"""Certificates for the Modbus/TCP Security tests, generated on the fly (never committed)."""

from __future__ import annotations

import datetime
import ipaddress
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from aiortu.transport import ROLE_OID

__all__ = ("Authority", "Issued", "der_utf8")

_NOW = datetime.datetime.now(datetime.UTC)


def der_utf8(text: str) -> bytes:
    """`text` as a DER UTF8String."""
    body = text.encode("utf-8")
    if len(body) < 0x80:
        return bytes((0x0C, len(body))) + body
    size = (len(body).bit_length() + 7) // 8
    return bytes((0x0C, 0x80 | size)) + len(body).to_bytes(size, "big") + body


@dataclass
class Issued:
    """A certificate and its key, written as PEM files."""

    certificate: x509.Certificate
    certfile: Path
    keyfile: Path

    @property
    def der(self) -> bytes:
        return self.certificate.public_bytes(serialization.Encoding.DER)


class Authority:
    """A certificate authority that issues server and client certificates into `directory`."""

    def __init__(self, directory: Path, name: str = "aiortu test CA") -> None:
        self.directory = directory
        self.name = name
        self.key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        self.certificate = (
            x509.CertificateBuilder()
            .subject_name(subject)
            .issuer_name(subject)
            .public_key(self.key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(_NOW - datetime.timedelta(days=1))
            .not_valid_after(_NOW + datetime.timedelta(days=30))
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(self.key, hashes.SHA256())
        )
        self.cafile = directory / f"{name.replace(' ', '-')}.pem"
        self.cafile.write_bytes(self.certificate.public_bytes(serialization.Encoding.PEM))

    def issue(
        self,
        name: str,
        *,
        role: str | None = None,
        role_value: bytes | None = None,
        server: bool = False,
        expired: bool = False,
    ) -> Issued:
        """A certificate for `name`: a server's (for 127.0.0.1 and localhost) or a client's with
        `role` (or the raw extension value `role_value`)."""
        key = ec.generate_private_key(ec.SECP256R1())
        start = _NOW - datetime.timedelta(days=10 if expired else 1)
        end = _NOW - datetime.timedelta(days=2) if expired else _NOW + datetime.timedelta(days=7)
        builder = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(self.certificate.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start)
            .not_valid_after(end)
        )
        if server:
            builder = builder.add_extension(
                x509.SubjectAlternativeName(
                    [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
                ),
                critical=False,
            )
        if role is not None or role_value is not None:
            value = role_value if role_value is not None else der_utf8(role or "")
            builder = builder.add_extension(
                x509.UnrecognizedExtension(x509.ObjectIdentifier(ROLE_OID), value),
                critical=False,
            )
        certificate = builder.sign(self.key, hashes.SHA256())
        certfile = self.directory / f"{name}.crt"
        keyfile = self.directory / f"{name}.key"
        certfile.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
        keyfile.write_bytes(
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.PKCS8,
                serialization.NoEncryption(),
            )
        )
        return Issued(certificate, certfile, keyfile)
