"""A client's certificate file, read as ``pendant users cert`` and ``pendant opcua trust``
read it (server/auth/certificates.py): PEM or DER, and refused, naming the file and why, when
it is not a certificate, has expired or is not valid yet. (The OPC UA face's own refusals, on
a live channel, are in test_opcua_security.py.)"""

from __future__ import annotations

from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from opcua_helpers import client_certificate

from server.auth.certificates import certificate_der, check_time


def test_a_valid_certificate_is_read_from_der_and_from_pem(tmp_path: Path) -> None:
    der = Path(client_certificate(tmp_path, "cell-pc").cert).read_bytes()
    pem = tmp_path / "cell-pc.pem"
    pem.write_bytes(x509.load_der_x509_certificate(der).public_bytes(Encoding.PEM))
    assert certificate_der(Path(tmp_path / "cell-pc-cert.der")) == der
    assert certificate_der(pem) == der
    assert check_time(x509.load_der_x509_certificate(der)) is None


@pytest.mark.parametrize(("starts", "lasts", "why"), [(-30, 10, "expired on"),
                                                      (5, 365, "not valid before")])
def test_a_certificate_out_of_its_validity_is_refused_naming_why(tmp_path: Path, starts: float,
                                                                 lasts: float, why: str) -> None:
    cert = Path(client_certificate(tmp_path, "old-pc", valid_from_days=starts,
                                   valid_days=lasts).cert)
    with pytest.raises(ValueError, match=why) as e:
        certificate_der(cert)
    assert str(cert) in str(e.value)


def test_a_file_that_is_no_certificate_is_refused_naming_it(tmp_path: Path) -> None:
    junk = tmp_path / "notes.txt"
    junk.write_text("-----BEGIN CERTIFICATE-----\nnot base64\n-----END CERTIFICATE-----\n")
    with pytest.raises(ValueError, match="notes.txt: not an X.509 certificate"):
        certificate_der(junk)
