"""SOAP 1.2 and WS-Security for ONVIF: namespaces, a hardened parser, envelopes, faults, UsernameToken digests.

What the ONVIF emulator needs to read requests and write replies (the driver reads replies through
its client library, zeep). Pure: bytes and strings in and out, the clock passed in.

The parser refuses what a camera must never process: a DOCTYPE (so no entity expansion, no
external entities: the "billion laughs" and XXE attacks), bodies over :data:`MAX_BODY` bytes,
nesting deeper than lxml's default limit; every refusal is a :class:`SoapError` with one line.
"""

from __future__ import annotations

import base64
import binascii
import datetime as dt
import hashlib
import hmac
from dataclasses import dataclass
from xml.sax.saxutils import escape

from lxml import etree

SOAP12 = "http://www.w3.org/2003/05/soap-envelope"
SOAP11 = "http://schemas.xmlsoap.org/soap/envelope/"
TDS = "http://www.onvif.org/ver10/device/wsdl"
TRT = "http://www.onvif.org/ver10/media/wsdl"
TPTZ = "http://www.onvif.org/ver20/ptz/wsdl"
TT = "http://www.onvif.org/ver10/schema"
TER = "http://www.onvif.org/ver10/error"
WSSE = "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-secext-1.0.xsd"
WSU = "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-wssecurity-utility-1.0.xsd"
PASSWORD_DIGEST = ("http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-username-token-profile-1.0"
                   "#PasswordDigest")
PASSWORD_TEXT = "http://docs.oasis-open.org/wss/2004/01/oasis-200401-wss-username-token-profile-1.0#PasswordText"

#: The generic spaces (ONVIF PTZ service specification, section 5.7).
SPACES = {
    "pan_tilt_position": "http://www.onvif.org/ver10/tptz/PanTiltSpaces/PositionGenericSpace",
    "zoom_position": "http://www.onvif.org/ver10/tptz/ZoomSpaces/PositionGenericSpace",
    "pan_tilt_translation": "http://www.onvif.org/ver10/tptz/PanTiltSpaces/TranslationGenericSpace",
    "zoom_translation": "http://www.onvif.org/ver10/tptz/ZoomSpaces/TranslationGenericSpace",
    "pan_tilt_velocity": "http://www.onvif.org/ver10/tptz/PanTiltSpaces/VelocityGenericSpace",
    "zoom_velocity": "http://www.onvif.org/ver10/tptz/ZoomSpaces/VelocityGenericSpace",
    "pan_tilt_speed": "http://www.onvif.org/ver10/tptz/PanTiltSpaces/GenericSpeedSpace",
    "zoom_speed": "http://www.onvif.org/ver10/tptz/ZoomSpaces/ZoomGenericSpeedSpace",
}

#: Largest request body a camera reads (bytes); ONVIF PTZ requests are well under 4 KiB.
MAX_BODY = 64 * 1024
#: How far a UsernameToken's Created may be from the camera's clock (s), as cameras allow.
CLOCK_SKEW_S = 300.0

_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False,
                          huge_tree=False, remove_comments=True, remove_pis=True)


class SoapError(ValueError):
    """A request that cannot be served: ``code`` (``Sender``/``Receiver``/``VersionMismatch``), ``subcode``
    (an ONVIF ``ter:`` code or ``""``) and one line of reason."""

    def __init__(self, reason: str, code: str = "Sender", subcode: str = "") -> None:
        super().__init__(reason)
        self.code, self.subcode = code, subcode


@dataclass(frozen=True)
class Request:
    """A parsed SOAP 1.2 request: the operation's namespace and name, its element, and the header."""

    namespace: str
    operation: str
    body: etree._Element
    header: etree._Element | None


def parse_request(data: bytes) -> Request:
    """Parse one SOAP request body; :class:`SoapError` (one line) for anything that is not one."""
    if len(data) > MAX_BODY:
        raise SoapError(f"request of {len(data)} bytes, at most {MAX_BODY}")
    if not data.strip():
        raise SoapError("empty request, expected a SOAP 1.2 envelope")
    try:
        root = etree.fromstring(data, _PARSER)
    except (etree.XMLSyntaxError, ValueError) as exc:
        raise SoapError(f"not well-formed XML: {str(exc).splitlines()[0][:200]}") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise SoapError("a DOCTYPE is not allowed in a SOAP message")
    if not isinstance(root.tag, str) or etree.QName(root).localname != "Envelope":
        raise SoapError("expected a SOAP Envelope element")
    if etree.QName(root).namespace == SOAP11:
        raise SoapError("SOAP 1.1 envelope; this service speaks SOAP 1.2", code="VersionMismatch")
    if etree.QName(root).namespace != SOAP12:
        raise SoapError(f"envelope namespace {etree.QName(root).namespace!r}, expected {SOAP12}",
                        code="VersionMismatch")
    header = root.find(f"{{{SOAP12}}}Header")
    body = root.find(f"{{{SOAP12}}}Body")
    if body is None:
        raise SoapError("the envelope has no Body")
    ops = [e for e in body if isinstance(e.tag, str)]
    if len(ops) != 1:
        raise SoapError(f"expected one operation in the Body, found {len(ops)}")
    q = etree.QName(ops[0])
    return Request(q.namespace or "", q.localname, ops[0], header)


def envelope(body: str, namespaces: dict[str, str] | None = None) -> bytes:
    """A SOAP 1.2 envelope around ``body`` (XML text using the prefixes tds, trt, tptz, tt, ter)."""
    ns = {"s": SOAP12, "tds": TDS, "trt": TRT, "tptz": TPTZ, "tt": TT, "ter": TER, **(namespaces or {})}
    decl = " ".join(f'xmlns:{k}="{v}"' for k, v in ns.items())
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<s:Envelope {decl}><s:Body>{body}</s:Body></s:Envelope>'
            .encode())


def fault(code: str, subcode: str, reason: str) -> bytes:
    """A SOAP 1.2 fault envelope (``code``: Sender, Receiver, VersionMismatch; ``subcode``: ``ter:...`` or "")."""
    sub = f"<s:Subcode><s:Value>{escape(subcode)}</s:Value></s:Subcode>" if subcode else ""
    return envelope(f"<s:Fault><s:Code><s:Value>s:{escape(code)}</s:Value>{sub}</s:Code>"
                    f'<s:Reason><s:Text xml:lang="en">{escape(reason)}</s:Text></s:Reason></s:Fault>')


def password_digest(nonce: bytes, created: str, password: str) -> str:
    """WS-Security UsernameToken digest: Base64(SHA-1(nonce + created + password))."""
    return base64.b64encode(hashlib.sha1(nonce + created.encode() + password.encode()).digest()).decode()


def _parse_created(text: str) -> dt.datetime:
    t = dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    return t if t.tzinfo else t.replace(tzinfo=dt.UTC)


def check_username_token(header: etree._Element | None, user: str, password: str, now: dt.datetime,
                         seen_nonces: set[bytes] | None = None) -> None:
    """Check the request's WS-Security UsernameToken (PasswordDigest, or PasswordText) against
    ``user``/``password``; :class:`SoapError` ``ter:NotAuthorized`` (one line) if it is missing or wrong.

    ``now`` (aware) bounds ``Created`` to :data:`CLOCK_SKEW_S`; ``seen_nonces`` (bounded by the
    caller) refuses a replayed nonce.
    """

    def refuse(why: str) -> SoapError:
        return SoapError(f"not authorised: {why}", "Sender", "ter:NotAuthorized")

    token = None if header is None else header.find(f"{{{WSSE}}}Security/{{{WSSE}}}UsernameToken")
    if token is None:
        raise refuse("no WS-Security UsernameToken")
    name = token.findtext(f"{{{WSSE}}}Username")
    pw = token.find(f"{{{WSSE}}}Password")
    if name is None or pw is None:
        raise refuse("UsernameToken without Username or Password")
    kind = pw.get("Type", PASSWORD_TEXT)
    given = pw.text or ""
    if kind == PASSWORD_TEXT:
        ok = hmac.compare_digest(given.encode(), password.encode())
    elif kind == PASSWORD_DIGEST:
        nonce_text = token.findtext(f"{{{WSSE}}}Nonce")
        created = token.findtext(f"{{{WSU}}}Created")
        if nonce_text is None or created is None:
            raise refuse("PasswordDigest without Nonce or Created")
        try:
            nonce = base64.b64decode(nonce_text.strip(), validate=True)
            when = _parse_created(created)
        except (binascii.Error, ValueError):
            raise refuse("malformed Nonce or Created") from None
        if abs((now - when).total_seconds()) > CLOCK_SKEW_S:
            raise refuse(f"Created {created.strip()[:40]} is more than {CLOCK_SKEW_S:g} s from the camera's clock")
        if seen_nonces is not None and nonce in seen_nonces:
            raise refuse("nonce replayed")
        ok = hmac.compare_digest(given.strip().encode(), password_digest(nonce, created, password).encode())
        if ok and seen_nonces is not None:
            seen_nonces.add(nonce)
    else:
        raise refuse(f"unknown password type {kind[:80]!r}")
    if not (ok and hmac.compare_digest(name.encode(), user.encode())):
        raise refuse("wrong user name or password")
