"""``bayesprog keystore create DIR --enclaves E ...``: a keystore of DDS Security (SROS2) for the
explorer and the robots that drive it, the files ``ros2 security create_keystore`` and
``create_enclave`` make, with each enclave's permissions narrowed to its part in the exchange.

The layout is sros2's::

    public/ca.cert.pem           the certificate authority (CA), self-signed
    private/ca.key.pem           its private key (readable by its owner only)
    public/identity_ca.cert.pem, public/permissions_ca.cert.pem       links to ca.cert.pem
    private/identity_ca.key.pem, private/permissions_ca.key.pem       links to ca.key.pem
    enclaves/governance.xml      what the domain protects: every topic authenticated,
                                 encrypted, read and written under access control
    enclaves/governance.p7s      the same, signed by the CA (S/MIME)
    enclaves/<enclave>/cert.pem, key.pem        the enclave's identity, issued by the CA
    enclaves/<enclave>/identity_ca.cert.pem, permissions_ca.cert.pem, governance.p7s  links
    enclaves/<enclave>/permissions.xml, .p7s    what it may publish and subscribe, signed

Keys are ECDSA on P-256 (prime256v1, which DDS Security 9.3.1 calls for), certificates X.509
signed with SHA-256, valid ten years (from a day before they are made); the signed documents
are S/MIME PKCS#7 with the content as clear text, detached, as sros2 signs them. All of it is
:mod:`cryptography`'s.

Permissions name DDS topics: a ROS topic ``/bayesprog/probe`` is ``rt/bayesprog/probe``, a
service ``S``'s request and reply ``rqSRequest`` and ``rrSReply``. Each enclave has one of
three parts (:data:`PARTS`):

- the explorer (``--explorer``, ``/bayesprog/explorer`` by default; the recorder runs in it
  too) publishes ``reply``, ``next_target``, the grids, ``path`` and ``shape``, and subscribes
  to ``probe``;
- a driver (every other enclave of ``--enclaves``) publishes ``probe`` and ``fingertip``, and
  subscribes to everything the explorer publishes;
- a viewer (``--viewers``, RViz) subscribes to what the explorer and the drivers publish, and
  publishes nothing of the exchange;

each in every namespace given (``--namespace``, ``/bayesprog`` by default), and with what every
ROS 2 node needs (sros2's common node policy): ``rosout``, ``parameter_events``, ``clock``, the
parameter and type-description services of its nodes, and ``ros_discovery_info`` (the graph
topic of Fast DDS's middleware).
"""

from __future__ import annotations

import datetime
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from bayesprog import BayesprogError

EXPLORER_ENCLAVE = "/bayesprog/explorer"
NAMESPACE = "/bayesprog"
#: the subject of the CA's certificate, sros2's
CA_NAME = "sros2CA"
#: how long the certificates hold
VALID_DAYS = 3650

#: what the explorer publishes, relative to its namespace (docs/robot.md, "The contract")
EXPLORER_OUT = ("reply", "next_target", "belief", "posterior", "saliency", "uncertainty",
                "inhibition", "path", "shape")
#: what a driver publishes, relative to the same namespace
DRIVER_OUT = ("probe", "fingertip")
#: the services every rclpy node serves (~/NAME)
NODE_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters",
                 "get_type_description", "list_parameters", "set_parameters",
                 "set_parameters_atomically")
#: the nodes of the explorer's enclave; a driver's or a viewer's nodes are the lab's own (any)
EXPLORER_NODES = ("bayesprog_explorer", "bayesprog_recorder")
#: an enclave's part in the exchange
PARTS = ("explorer", "driver", "viewer")


@dataclass(frozen=True)
class Grant:
    """The DDS topics an enclave may publish and subscribe to."""

    publish: tuple[str, ...]
    subscribe: tuple[str, ...]


def _rt(namespace: str, names: Sequence[str]) -> list[str]:
    return [f"rt{namespace.rstrip('/')}/{name}" for name in names]


def _services(nodes: Sequence[str]) -> list[str]:
    """The request and reply topics of every node's services (requested and answered alike)."""
    return [f"{kind}{node}/{service}{suffix}" for node in nodes for service in NODE_SERVICES
            for kind, suffix in (("rq", "Request"), ("rr", "Reply"))]


def grant(part: str, namespaces: Sequence[str] = (NAMESPACE,)) -> Grant:
    """What an enclave of ``part`` (explorer, driver, viewer) may publish and subscribe to.

    >>> g = grant("driver")
    >>> "rt/bayesprog/probe" in g.publish, "rt/bayesprog/reply" in g.publish
    (True, False)
    >>> "rt/bayesprog/probe" in grant("explorer").subscribe
    True
    """
    if part not in PARTS:
        raise ValueError(f"unknown part {part!r}: expected one of {', '.join(PARTS)}")
    publish, subscribe = ["rt/rosout", "rt/parameter_events"], ["rt/parameter_events", "rt/clock"]
    if part == "explorer":
        nodes = [f"/{ns.strip('/')}/{node}".replace("//", "/") for ns in namespaces
                 for node in EXPLORER_NODES]
    else:
        nodes = ["/*"]  # the lab's own nodes, of any name and namespace
    publish += _services(nodes)
    subscribe += _services(nodes)
    for ns in namespaces:
        if part == "explorer":
            publish += _rt(ns, EXPLORER_OUT)
            subscribe += _rt(ns, ["probe"])
        elif part == "driver":
            publish += _rt(ns, DRIVER_OUT)
            subscribe += _rt(ns, EXPLORER_OUT)
        else:
            subscribe += _rt(ns, (*EXPLORER_OUT, "fingertip"))
    return Grant(tuple(sorted(set(publish))), tuple(sorted(set(subscribe))))


_ENCLAVE = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")


def check_enclave(name: str) -> str:
    """An enclave's name as ROS 2 spells it: absolute, of ``/``-separated words of letters,
    digits and underscores, none starting with a digit."""
    if not _ENCLAVE.fullmatch(name):
        raise BayesprogError(f"enclave {name!r}: expected an absolute name such as "
                             f"{EXPLORER_ENCLAVE} (words of letters, digits and underscores, "
                             "each after a /, none starting with a digit)")
    return name


def check_namespace(name: str) -> str:
    if name != "/" and not _ENCLAVE.fullmatch(name.rstrip("/")):
        raise BayesprogError(f"--namespace {name!r}: expected an absolute namespace such as "
                             f"{NAMESPACE}")
    return name


def _crypto() -> Any:
    """cryptography's modules, or a line saying how to install them."""
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.hazmat.primitives.serialization import pkcs7
    except ImportError:
        raise BayesprogError('keystore needs the cryptography library: install it with pip '
                             'install "bayesprog[ros]"') from None
    return x509, hashes, serialization, ec, pkcs7


class Keystore:
    """An SROS2 keystore at ``root``: its CA made, or read back when it is there."""

    def __init__(self, root: Path, domain: int | None = None):
        self.root = root
        x509, self._hashes, self._ser, self._ec, self._pkcs7 = _crypto()
        self._x509 = x509
        cert, key = root / "public" / "ca.cert.pem", root / "private" / "ca.key.pem"
        if cert.is_file() and key.is_file():
            self.ca = x509.load_pem_x509_certificate(cert.read_bytes())
            self.ca_key = self._ser.load_pem_private_key(key.read_bytes(), None)
            self.made_ca = False
        else:
            if root.exists() and any(root.iterdir()):
                raise BayesprogError(f"{root} is a folder with files but no keystore (no "
                                     "public/ca.cert.pem and private/ca.key.pem): expected a new "
                                     "folder or a keystore to add enclaves to")
            for sub in ("public", "private", "enclaves"):
                (root / sub).mkdir(parents=True, exist_ok=True)
            name = x509.Name([x509.NameAttribute(x509.oid.NameOID.COMMON_NAME, CA_NAME)])
            self.ca, self.ca_key = self._certificate(name, None)
            cert.write_bytes(self._pem(self.ca))
            _write_private(key, self._key_pem(self.ca_key))
            for which in ("identity_ca", "permissions_ca"):
                _link(root / "public" / f"{which}.cert.pem", Path("ca.cert.pem"))
                _link(root / "private" / f"{which}.key.pem", Path("ca.key.pem"))
            self.made_ca = True
        governance = root / "enclaves" / "governance.xml"
        if governance.is_file():
            found = _governed_domain(governance)
            if domain is not None and domain != found:
                raise BayesprogError(f"{governance} governs domain {found}, not {domain}: "
                                     "expected the keystore's domain (ROS_DOMAIN_ID, --domain), "
                                     "or a new keystore for another domain")
            self.domain = found
        else:
            self.domain = 0 if domain is None else domain
            governance.write_bytes(governance_xml(self.domain))
        signed = root / "enclaves" / "governance.p7s"
        if not signed.is_file():
            signed.write_bytes(self.sign(governance.read_bytes()))

    # the pieces -------------------------------------------------------------------------------
    def _certificate(self, subject: Any, issuer: tuple[Any, Any] | None) -> tuple[Any, Any]:
        """A new P-256 key and its certificate: the CA's own (``issuer`` None) or issued by
        ``issuer`` (certificate, key)."""
        x509 = self._x509
        key = self._ec.generate_private_key(self._ec.SECP256R1())
        now = datetime.datetime.now(datetime.UTC)
        builder = (x509.CertificateBuilder()
                   .issuer_name(subject if issuer is None else issuer[0].subject)
                   .subject_name(subject)
                   .serial_number(x509.random_serial_number())
                   # a day earlier, as sros2 does: a clock a little behind still takes it
                   .not_valid_before(now - datetime.timedelta(days=1))
                   .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
                   .public_key(key.public_key())
                   .add_extension(x509.BasicConstraints(ca=issuer is None,
                                                        path_length=1 if issuer is None else None),
                                  critical=issuer is None))
        return builder.sign(key if issuer is None else issuer[1], self._hashes.SHA256()), key

    def _pem(self, cert: Any) -> bytes:
        return bytes(cert.public_bytes(self._ser.Encoding.PEM))

    def _key_pem(self, key: Any) -> bytes:
        ser = self._ser
        return bytes(key.private_bytes(ser.Encoding.PEM, ser.PrivateFormat.PKCS8,
                                       ser.NoEncryption()))

    def sign(self, content: bytes) -> bytes:
        """``content`` signed by the CA: S/MIME, clear text, detached (as sros2 signs)."""
        pkcs7 = self._pkcs7
        return bytes(pkcs7.PKCS7SignatureBuilder().set_data(content)
                     .add_signer(self.ca, self.ca_key, self._hashes.SHA256())
                     .sign(self._ser.Encoding.SMIME,
                           [pkcs7.PKCS7Options.Text, pkcs7.PKCS7Options.DetachedSignature]))

    def add_enclave(self, name: str, part: str, namespaces: Sequence[str]) -> Path:
        """Make enclave ``name`` (its identity kept when it is there) with the permissions of
        ``part``; its folder."""
        x509 = self._x509
        folder = self.root / "enclaves" / name.strip("/")
        folder.mkdir(parents=True, exist_ok=True)
        for which in ("identity_ca", "permissions_ca"):
            _link(folder / f"{which}.cert.pem",
                  Path(os.path.relpath(self.root / "public" / f"{which}.cert.pem", folder)))
        _link(folder / "governance.p7s",
              Path(os.path.relpath(self.root / "enclaves" / "governance.p7s", folder)))
        cert_path, key_path = folder / "cert.pem", folder / "key.pem"
        if cert_path.is_file() and key_path.is_file():
            cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        else:
            subject = x509.Name([x509.NameAttribute(x509.oid.NameOID.COMMON_NAME, name)])
            cert, key = self._certificate(subject, (self.ca, self.ca_key))
            _write_private(key_path, self._key_pem(key))
            cert_path.write_bytes(self._pem(cert))
        permissions = permissions_xml(name, grant(part, namespaces), self.domain,
                                      cert.not_valid_before_utc, cert.not_valid_after_utc)
        (folder / "permissions.xml").write_bytes(permissions)
        (folder / "permissions.p7s").write_bytes(self.sign(permissions))
        return folder


def _governed_domain(governance: Path) -> int:
    """The domain a governance file is for."""
    try:
        found = ElementTree.parse(governance).find("domain_access_rules/domain_rule/domains/id")
        return int((found.text or "").strip()) if found is not None else 0
    except (ElementTree.ParseError, ValueError):
        raise BayesprogError(f"{governance}: expected sros2's governance, with the domain's "
                             "id") from None


def _link(path: Path, target: Path) -> None:
    """``path`` a symbolic link to ``target`` (relative to its folder), as sros2 makes them."""
    if path.is_symlink() or path.exists():
        if path.resolve() == (path.parent / target).resolve():
            return
        path.unlink()
    path.symlink_to(target)


def _write_private(path: Path, content: bytes) -> None:
    """A private key, readable by its owner only."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(content)
    os.chmod(path, 0o600)


# the documents --------------------------------------------------------------------------------
_DDS_SCHEMA = "http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_{}.xsd"
_XSI = "http://www.w3.org/2001/XMLSchema-instance"


def _document(root: ElementTree.Element) -> bytes:
    ElementTree.indent(root, "  ")
    return ElementTree.tostring(root, encoding="unicode").encode() + b"\n"


def _dds(kind: str) -> ElementTree.Element:
    return ElementTree.Element("dds", {"xmlns:xsi": _XSI,
                                       "xsi:noNamespaceSchemaLocation": _DDS_SCHEMA.format(kind)})


def _add(parent: ElementTree.Element, tag: str, text: str | None = None) -> ElementTree.Element:
    child = ElementTree.SubElement(parent, tag)
    child.text = text
    return child


def governance_xml(domain: int) -> bytes:
    """sros2's governance: no unauthenticated participant; discovery, liveliness and every
    topic's data encrypted, messages signed; reading and writing every topic under access
    control.

    >>> b"<allow_unauthenticated_participants>false" in governance_xml(7)
    True
    """
    dds = _dds("governance")
    rule = _add(_add(dds, "domain_access_rules"), "domain_rule")
    _add(_add(rule, "domains"), "id", str(domain))
    for tag, text in (("allow_unauthenticated_participants", "false"),
                      ("enable_join_access_control", "true"),
                      ("discovery_protection_kind", "ENCRYPT"),
                      ("liveliness_protection_kind", "ENCRYPT"),
                      ("rtps_protection_kind", "SIGN")):
        _add(rule, tag, text)
    topic = _add(_add(rule, "topic_access_rules"), "topic_rule")
    for tag, text in (("topic_expression", "*"), ("enable_discovery_protection", "true"),
                      ("enable_liveliness_protection", "true"),
                      ("enable_read_access_control", "true"),
                      ("enable_write_access_control", "true"),
                      ("metadata_protection_kind", "ENCRYPT"),
                      ("data_protection_kind", "ENCRYPT")):
        _add(topic, tag, text)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + _document(dds)


def permissions_xml(enclave: str, allowed: Grant, domain: int, not_before: datetime.datetime,
                    not_after: datetime.datetime) -> bytes:
    """The permissions of ``enclave`` as sros2's template writes them: one grant for the
    subject ``CN=<enclave>``, valid as its certificate is, that allows ``allowed`` in
    ``domain`` (and ``ros_discovery_info``) and denies everything else."""
    dds = _dds("permissions")
    entry = _add(_add(dds, "permissions"), "grant")
    entry.set("name", enclave)
    _add(entry, "subject_name", f"CN={enclave}")
    validity = _add(entry, "validity")
    for tag, when in (("not_before", not_before), ("not_after", not_after)):
        _add(validity, tag, when.replace(tzinfo=None).isoformat())

    def rule(publish: Sequence[str], subscribe: Sequence[str]) -> None:
        allow = _add(entry, "allow_rule")
        _add(_add(allow, "domains"), "id", str(domain))
        for tag, topics in (("publish", publish), ("subscribe", subscribe)):
            if topics:
                listed = _add(_add(allow, tag), "topics")
                for topic in topics:
                    _add(listed, "topic", topic)

    rule(allowed.publish, allowed.subscribe)
    rule(["ros_discovery_info"], ["ros_discovery_info"])
    _add(entry, "default", "DENY")
    return _document(dds)


# the command ----------------------------------------------------------------------------------
def create_keystore(root: Path, enclaves: Sequence[str], explorer: str = EXPLORER_ENCLAVE,
                    viewers: Sequence[str] = (), namespaces: Sequence[str] = (NAMESPACE,),
                    domain: int | None = None) -> dict[str, str]:
    """Make the keystore at ``root`` (or add to the one there) with ``enclaves``: ``explorer``
    serves, every other drives; and the ``viewers``. The domain is ``domain``, else
    ``ROS_DOMAIN_ID``'s, else the keystore's when there is one, else 0 (sros2 takes
    ``ROS_DOMAIN_ID``'s or 0). Returns each enclave's part."""
    for name in (*enclaves, *viewers, explorer):
        check_enclave(name)
    for ns in namespaces:
        check_namespace(ns)
    both = sorted(set(enclaves) & set(viewers))
    if both:
        raise BayesprogError(f"--viewers: {', '.join(both)} also among --enclaves: expected "
                             "each enclave once, with one part")
    if domain is None and os.environ.get("ROS_DOMAIN_ID", "").strip():
        text = os.environ["ROS_DOMAIN_ID"].strip()
        if not (text.isascii() and text.isdigit() and int(text) <= 232):
            raise BayesprogError(f"ROS_DOMAIN_ID={text!r}: expected an integer from 0 to 232")
        domain = int(text)
    if domain is not None and not 0 <= domain <= 232:
        raise BayesprogError(f"--domain: expected an integer from 0 to 232, found {domain}")
    store = Keystore(root, domain)
    parts = {name: "explorer" if name == explorer else "driver" for name in enclaves}
    parts.update({name: "viewer" for name in viewers})
    for name, part in parts.items():
        store.add_enclave(name, part, namespaces)
    return parts
