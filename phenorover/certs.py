"""Certificates for mutual TLS between machines: one CA, a key and certificate per machine.

``phenorover certs init`` makes the certificate authority (``ca.pem``, ``ca.key``);
``phenorover certs issue MACHINE`` makes ``MACHINE.pem`` and ``MACHINE.key`` signed by
it. A machine's certificate carries its name as the common name, which is what the
other routers' access control matches (see :mod:`common.acl`), and as a DNS subject
alternative name beside any ``hosts`` given (``rover.local``: the name the other
machines connect to, checked by TLS). Keys are ECDSA P-256, written mode 0600, and no
file is replaced unless ``force`` is set.

The functions that make keys and certificates are pure; :func:`init_ca` and
:func:`issue_files` are the file-writing shell the CLI calls.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import re
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from common.files import atomic_path

DEFAULT_DIR = Path("deploy/certs")
CA_NAME = "phenorover-ca"
LOOPBACK_HOSTS = ("localhost", "127.0.0.1")
# a machine name is a certificate common name and a DNS name: one DNS label
_MACHINE = re.compile(r"^[a-z0-9]([a-z0-9-]{0,61}[a-z0-9])?$")

Key = ec.EllipticCurvePrivateKey


class CertError(ValueError):
    """A certificate could not be made or read; the message is one line."""


def _name(cn: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])


def _validity(days: int) -> tuple[datetime.datetime, datetime.datetime]:
    # a minute in the past: machines whose clocks disagree a little still accept it
    start = datetime.datetime.now(datetime.UTC) - datetime.timedelta(minutes=1)
    return start, start + datetime.timedelta(days=days)


def check_machine(name: str) -> None:
    """Raise CertError unless ``name`` can be a common name and a DNS label."""
    if not _MACHINE.match(name):
        raise CertError(
            f"machine name {name!r}: use lower-case letters, digits and '-' "
            "(it becomes the certificate's common name and a DNS name)"
        )


def _usage(ca: bool) -> x509.KeyUsage:
    """A CA's key signs certificates and CRLs only; a machine's signs its TLS
    handshakes only (ECDHE: no key encipherment)."""
    return x509.KeyUsage(
        digital_signature=not ca,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=ca,
        crl_sign=ca,
        encipher_only=False,
        decipher_only=False,
    )


def make_ca(name: str = CA_NAME, days: int = 3650) -> tuple[Key, x509.Certificate]:
    """A new self-signed CA key and certificate (may sign machine certificates only)."""
    key = ec.generate_private_key(ec.SECP256R1())
    start, end = _validity(days)
    ski = x509.SubjectKeyIdentifier.from_public_key(key.public_key())
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(_name(name))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_usage(ca=True), critical=True)
        .add_extension(ski, critical=False)
        .sign(key, hashes.SHA256())
    )
    return key, cert


def _san(machine: str, hosts: list[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for h in dict.fromkeys([machine, *hosts]):  # ordered, no duplicates
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return x509.SubjectAlternativeName(names)


def issue(
    ca_key: Key, ca_cert: x509.Certificate, machine: str, hosts: list[str], days: int = 825
) -> tuple[Key, x509.Certificate]:
    """A new key and certificate for ``machine``, signed by the CA, valid as TLS server
    and client (a router both listens and connects). Raises CertError on a bad name."""
    check_machine(machine)
    key = ec.generate_private_key(ec.SECP256R1())
    start, end = _validity(days)
    ca_ski = ca_cert.extensions.get_extension_for_class(x509.SubjectKeyIdentifier).value
    aki = x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_ski)
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(machine))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(min(end, ca_cert.not_valid_after_utc))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(_usage(ca=False), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(_san(machine, hosts), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(aki, critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    return key, cert


def key_pem(key: Key) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def cert_pem(cert: x509.Certificate) -> bytes:
    return cert.public_bytes(serialization.Encoding.PEM)


def read_cert(path: Path) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except OSError as exc:
        raise CertError(f"{path}: cannot read: {exc.strerror}") from None
    except ValueError:
        raise CertError(f"{path}: not a PEM certificate") from None


def read_key(path: Path) -> Key:
    try:
        key = serialization.load_pem_private_key(path.read_bytes(), password=None)
    except OSError as exc:
        raise CertError(f"{path}: cannot read: {exc.strerror}") from None
    except (ValueError, TypeError):
        raise CertError(f"{path}: not an unencrypted PEM private key") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise CertError(f"{path}: not an EC key as `phenorover certs` makes")
    return key


def common_name(cert: x509.Certificate) -> str:
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(attrs[0].value) if attrs else ""


def _write(path: Path, data: bytes, mode: int) -> None:
    """``data`` to ``path`` with ``mode``, whole or not at all: a replaced key stays the
    old one until the new one is complete (whether to replace is
    :func:`_refuse_existing`'s)."""
    try:
        with atomic_path(path) as tmp:
            # created with its mode: a key is never readable by others, not for a moment
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.chmod(tmp, mode)  # the umask may have narrowed it; keys stay 0600 either way
    except OSError as exc:
        raise CertError(f"{path}: cannot write: {exc.strerror}") from None


def _refuse_existing(paths: list[Path], force: bool) -> None:
    # check every file before writing any, so a refusal leaves the folder as it was
    if not force:
        for p in paths:
            if p.exists():
                raise CertError(f"{p} exists (use --force to replace it)")


def init_ca(folder: Path = DEFAULT_DIR, force: bool = False, days: int = 3650) -> list[Path]:
    """Make ``folder/ca.pem`` and ``folder/ca.key`` (0600); returns the paths written."""
    cert_path, key_path = folder / "ca.pem", folder / "ca.key"
    _refuse_existing([cert_path, key_path], force)
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    except OSError as exc:
        raise CertError(f"{folder}: cannot create: {exc.strerror}") from None
    key, cert = make_ca(days=days)
    _write(key_path, key_pem(key), 0o600)
    _write(cert_path, cert_pem(cert), 0o644)
    return [cert_path, key_path]


def issue_files(
    machine: str,
    folder: Path = DEFAULT_DIR,
    hosts: list[str] | None = None,
    force: bool = False,
    days: int = 825,
) -> list[Path]:
    """Make ``folder/MACHINE.pem`` and ``folder/MACHINE.key`` (0600) signed by the CA in
    ``folder``; returns the paths written. Raises CertError (one line) on any problem."""
    check_machine(machine)
    ca_cert_path, ca_key_path = folder / "ca.pem", folder / "ca.key"
    if not ca_key_path.exists():
        raise CertError(f"{ca_key_path}: no CA here (run `phenorover certs init` first)")
    ca_cert, ca_key = read_cert(ca_cert_path), read_key(ca_key_path)
    cert_path, key_path = folder / f"{machine}.pem", folder / f"{machine}.key"
    _refuse_existing([cert_path, key_path], force)
    key, cert = issue(ca_key, ca_cert, machine, hosts or [], days=days)
    _write(key_path, key_pem(key), 0o600)
    _write(cert_path, cert_pem(cert), 0o644)
    return [cert_path, key_path]


def tls_problems(
    root_ca: Path, certificate: Path | None, key: Path | None, machine: str
) -> list[str]:
    """What is wrong with a machine's TLS files, a line each (none: they will do): each
    readable, the certificate signed by the CA and named after the machine (the other
    routers' access control knows it by that name), the key its own and private."""
    problems: list[str] = []
    ca: x509.Certificate | None = None
    try:
        ca = read_cert(root_ca)
    except CertError as exc:
        problems.append(f"root_ca {exc}")
    cert: x509.Certificate | None = None
    if certificate is not None:
        try:
            cert = read_cert(certificate)
            if ca is not None:
                cert.verify_directly_issued_by(ca)
        except CertError as exc:
            problems.append(f"certificate {exc}")
        except (ValueError, TypeError, InvalidSignature):
            problems.append(f"certificate {certificate}: not signed by {root_ca}")
        if cert is not None and common_name(cert) != machine:
            problems.append(
                f"certificate {certificate}: common name {common_name(cert)!r}, not the "
                f"machine {machine!r}: the other machines' access control would not know it"
            )
    if key is not None:
        try:
            k = read_key(key)
            if cert is not None and k.public_key() != cert.public_key():
                problems.append(f"private_key {key}: not the key of {certificate}")
            if key.stat().st_mode & 0o077:
                problems.append(f"private_key {key}: readable by others (chmod 600 it)")
        except CertError as exc:
            problems.append(f"private_key {exc}")
    return problems
