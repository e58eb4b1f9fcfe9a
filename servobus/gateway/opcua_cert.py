"""The gateway's self-signed OPC UA certificate: its SubjectAltName names what is served.

Decision (issue 36, docs/gateway.md "Security"): a client checks that the server's
certificate names the host it connected to (OPC 10000-4 6.1.3), so the SAN carries the
ApplicationUri (unique per gateway), the PC's host name, the endpoint's host when it is a
name, and its address when it is one (for a wildcard endpoint, 0.0.0.0 or ::, every
address the host name resolves to). A kept certificate whose SAN lacks one of them, or
names another ApplicationUri, is made anew with the same key; one that has them all is kept.
"""

from __future__ import annotations

import ipaddress
import socket
from pathlib import Path

from asyncua.crypto.cert_gen import (
    dump_private_key_as_pem,
    generate_private_key,
    generate_self_signed_app_certificate,
)
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding, load_pem_private_key
from cryptography.x509.oid import ExtendedKeyUsageOID

Address = ipaddress.IPv4Address | ipaddress.IPv6Address
WILDCARDS = {"0.0.0.0", "::", ""}


def served_names(host: str) -> tuple[list[str], list[Address]]:
    """The DNS names and IP addresses a certificate for an endpoint on ``host`` names."""
    here = socket.gethostname()
    names = [here]
    addresses: list[Address] = []
    if host in WILDCARDS:
        try:
            infos = socket.getaddrinfo(here, None)
        except OSError:  # a host name that does not resolve: the name alone
            infos = []
        for info in infos:
            address = ipaddress.ip_address(str(info[4][0]).split("%")[0])
            if address not in addresses:
                addresses.append(address)
        return names, addresses
    try:
        addresses.append(ipaddress.ip_address(host))
    except ValueError:
        if host not in names:
            names.append(host)
    return names, addresses


def wanted_san(app_uri: str, host: str) -> list[x509.GeneralName]:
    names, addresses = served_names(host)
    return [x509.UniformResourceIdentifier(app_uri), *(x509.DNSName(n) for n in names),
            *(x509.IPAddress(a) for a in addresses)]


def ensure_certificate(key_path: Path, cert_path: Path, app_uri: str, host: str) -> None:
    """Make the key (0600) when missing, and the certificate (0600) when missing or when its
    SAN does not name every entry of :func:`wanted_san`."""
    if key_path.is_file():
        key = load_pem_private_key(key_path.read_bytes(), None)
    else:
        key = generate_private_key()
        key_path.write_bytes(dump_private_key_as_pem(key))
    key_path.chmod(0o600)
    wanted = wanted_san(app_uri, host)
    if cert_path.is_file() and _covers(cert_path.read_bytes(), wanted):
        return
    cert = generate_self_signed_app_certificate(
        key, "servobus gateway", {}, wanted,
        extended=[ExtendedKeyUsageOID.SERVER_AUTH], days=365)
    cert_path.write_bytes(cert.public_bytes(Encoding.DER))
    cert_path.chmod(0o600)


def _covers(der: bytes, wanted: list[x509.GeneralName]) -> bool:
    try:
        cert = x509.load_der_x509_certificate(der)
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except (ValueError, x509.ExtensionNotFound):
        return False
    uris = san.get_values_for_type(x509.UniformResourceIdentifier)
    return all(entry in san for entry in wanted) and uris == [
        e.value for e in wanted if isinstance(e, x509.UniformResourceIdentifier)]
