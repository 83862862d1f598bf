"""The gateway's OPC UA security: certificate, policies, identity tokens, client check.

With a certificate the server offers SecurityPolicy Basic256Sha256 with mode
SignAndEncrypt only (None too with ``allow_insecure``); without one, None only (a test
bench).  Username tokens always, anonymous ones only when allowed.  A client
certificate must pass asyncua's own checks and be issued by the cell's OPC UA authority
(:func:`client_validator`).  docs/opcua.md, "Security".
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

from plugcell.devices.opcua.certificates import uri_of, verify_issued

log = logging.getLogger("plugcell.devices.opcua")


@dataclass(frozen=True)
class GatewaySecurity:
    """The server's certificate and what it accepts (docs/opcua.md, "Security")."""

    certificate: Path | None = None
    private_key: Path | None = None
    trusted_ca: Path | None = None
    """Accept client application certificates issued by this CA only (PEM)."""
    allow_insecure: bool = False
    """Also offer SecurityPolicy None (messages in clear)."""


async def configure_security(server: Server, sec: GatewaySecurity, anonymous: bool) -> None:
    """Identity tokens, security policies, certificate and client check of ``server``."""
    tokens: list[type] = [ua.UserNameIdentityToken]
    if anonymous:
        tokens.append(ua.AnonymousIdentityToken)
    server.set_identity_tokens(tokens)
    if sec.certificate is None:
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        return
    uri = uri_of(sec.certificate)
    if uri:  # the application URI must be the certificate's (OPC 10000-4 §6.1.3)
        await server.set_application_uri(uri)
    await server.load_certificate(str(sec.certificate), format="PEM")
    await server.load_private_key(str(sec.private_key), format="PEM")
    policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
    if sec.allow_insecure:
        policies.append(ua.SecurityPolicyType.NoSecurity)
    server.set_security_policy(policies)
    if sec.trusted_ca is not None:
        server.set_certificate_validator(client_validator(sec.trusted_ca))


def client_validator(authority: Path) -> Any:
    """asyncua's certificate check of a connecting client, plus: issued by ``authority``.

    asyncua's own validator checks the validity period, the application URI against
    the certificate, the key usages and the client-auth extended key usage; a client
    certificate that another authority issued is refused ``BadCertificateUntrusted``.
    """
    checks = CertificateValidator(
        CertificateValidatorOptions.EXT_VALIDATION | CertificateValidatorOptions.PEER_CLIENT
    )

    async def validate(certificate: Any, description: ua.ApplicationDescription) -> None:
        await checks.validate(certificate, description)
        why = verify_issued(certificate, authority)
        if why:
            log.warning("opcua: client certificate refused: %s", why)
            raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)

    return validate
