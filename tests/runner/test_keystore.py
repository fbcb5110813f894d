"""``bayesprog keystore create``: the files of sros2's keystore and enclaves, their keys and
certificates checked with cryptography, their signatures with OpenSSL's own ``smime -verify``
(an implementation of S/MIME other than the one that signed them), and each enclave's
permissions narrowed to its part. That the permissions cover every topic and service the nodes
create is checked against the nodes themselves, over DDS, in test_ros_security.py."""

from __future__ import annotations

import datetime
import os
import shutil
import stat
import subprocess
import sys
from fnmatch import fnmatchcase
from pathlib import Path
from xml.etree import ElementTree

import pytest
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec

from runner.robot.keystore import EXPLORER_OUT, grant

BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))
ENCLAVES = ("/bayesprog/explorer", "/bayesprog/driver")

#: what sros2's create_keystore and create_enclave make, and where its links point
LAYOUT = {
    "public/ca.cert.pem": None, "private/ca.key.pem": None,
    "public/identity_ca.cert.pem": "ca.cert.pem", "public/permissions_ca.cert.pem": "ca.cert.pem",
    "private/identity_ca.key.pem": "ca.key.pem", "private/permissions_ca.key.pem": "ca.key.pem",
    "enclaves/governance.xml": None, "enclaves/governance.p7s": None,
    **{f"enclaves{e}/{name}": target for e in ENCLAVES for name, target in (
        ("cert.pem", None), ("key.pem", None), ("permissions.xml", None),
        ("permissions.p7s", None), ("governance.p7s", "../../governance.p7s"),
        ("identity_ca.cert.pem", "../../../public/identity_ca.cert.pem"),
        ("permissions_ca.cert.pem", "../../../public/permissions_ca.cert.pem"))},
}

#: sros2's default governance (policy/defaults/dds/governance.xml), element by element
GOVERNANCE = {
    "allow_unauthenticated_participants": "false", "enable_join_access_control": "true",
    "discovery_protection_kind": "ENCRYPT", "liveliness_protection_kind": "ENCRYPT",
    "rtps_protection_kind": "SIGN",
    "topic_access_rules/topic_rule/topic_expression": "*",
    "topic_access_rules/topic_rule/enable_discovery_protection": "true",
    "topic_access_rules/topic_rule/enable_liveliness_protection": "true",
    "topic_access_rules/topic_rule/enable_read_access_control": "true",
    "topic_access_rules/topic_rule/enable_write_access_control": "true",
    "topic_access_rules/topic_rule/metadata_protection_kind": "ENCRYPT",
    "topic_access_rules/topic_rule/data_protection_kind": "ENCRYPT",
}


def create(root: Path, *args: str, domain: str = "23") -> subprocess.CompletedProcess:
    return subprocess.run([BAYESPROG, "keystore", "create", str(root), *args],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "ROS_DOMAIN_ID": domain})


@pytest.fixture(scope="module")
def keystore(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("lab") / "keystore"
    made = create(root, "--enclaves", *ENCLAVES, "--viewers", "/bayesprog/rviz")
    assert made.returncode == 0, made.stderr
    assert "/bayesprog/explorer (explorer), /bayesprog/driver (driver), /bayesprog/rviz " \
           "(viewer)" in made.stdout and "domain 23" in made.stdout
    return root


def allowed(root: Path, enclave: str) -> dict[str, list[str]]:
    """The DDS topics an enclave's permissions allow, by publish and subscribe."""
    doc = ElementTree.parse(root / "enclaves" / enclave.strip("/") / "permissions.xml")
    found: dict[str, list[str]] = {"publish": [], "subscribe": []}
    for rule in doc.iterfind("permissions/grant/allow_rule"):
        for kind in found:
            found[kind] += [t.text or "" for t in rule.iterfind(f"{kind}/topics/topic")]
    return found


def may(root: Path, enclave: str, kind: str, topic: str) -> bool:
    """Whether the enclave may ``kind`` (publish, subscribe) ``topic``, as DDS Security reads
    permissions: a topic matches an allowed expression (fnmatch), and the default denies."""
    return any(fnmatchcase(topic, pattern) for pattern in allowed(root, enclave)[kind])


def test_the_files_are_sros2s(keystore):
    for relative, target in LAYOUT.items():
        path = keystore / relative
        assert path.is_file(), relative
        if target is None:
            assert not path.is_symlink(), relative
        else:
            assert path.is_symlink() and os.readlink(path) == target, relative
    for key in ["private/ca.key.pem", *(f"enclaves{e}/key.pem" for e in ENCLAVES)]:
        assert stat.S_IMODE((keystore / key).stat().st_mode) == 0o600, key


def test_the_ca_signs_every_enclaves_identity_on_p256(keystore):
    ca = x509.load_pem_x509_certificate((keystore / "public/ca.cert.pem").read_bytes())
    assert ca.subject.rfc4514_string() == "CN=sros2CA" and ca.issuer == ca.subject
    ca.verify_directly_issued_by(ca)
    constraints = ca.extensions.get_extension_for_class(x509.BasicConstraints)
    assert constraints.critical and constraints.value.ca
    for enclave in ENCLAVES:
        cert = x509.load_pem_x509_certificate(
            (keystore / f"enclaves{enclave}/cert.pem").read_bytes())
        assert cert.subject.rfc4514_string() == f"CN={enclave}"
        cert.verify_directly_issued_by(ca)  # raises unless the CA's key signed it
        key = cert.public_key()
        assert isinstance(key, ec.EllipticCurvePublicKey) and key.curve.name == "secp256r1"
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        days = (cert.not_valid_after_utc - cert.not_valid_before_utc).days
        assert days == 3651  # ten years from a day before it was made, as sros2's
        assert cert.not_valid_before_utc < datetime.datetime.now(datetime.UTC)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command "
                    "(.ci/run installs it)")
def test_openssl_verifies_every_signed_document_against_the_ca(keystore, tmp_path):
    signed = ["enclaves/governance.p7s", *(f"enclaves{e}/permissions.p7s" for e in ENCLAVES),
              *(f"enclaves{e}/governance.p7s" for e in ENCLAVES)]
    for name in signed:
        out = tmp_path / "content"
        check = subprocess.run(["openssl", "smime", "-verify", "-text", "-in",
                                str(keystore / name), "-CAfile",
                                str(keystore / "public/permissions_ca.cert.pem"), "-out",
                                str(out)], capture_output=True, text=True, timeout=60)
        assert check.returncode == 0, (name, check.stderr)
        plain = keystore / name.replace(".p7s", ".xml")
        if name.count("/") == 1 or "permissions" in name:
            assert out.read_bytes().replace(b"\r\n", b"\n") == plain.read_bytes(), name
    # a document changed after it was signed is refused
    tampered = tmp_path / "tampered.p7s"
    tampered.write_bytes((keystore / f"enclaves{ENCLAVES[1]}/permissions.p7s").read_bytes()
                         .replace(b"rt/bayesprog/probe", b"rt/bayesprog/reply"))
    check = subprocess.run(["openssl", "smime", "-verify", "-text", "-in", str(tampered),
                            "-CAfile", str(keystore / "public/ca.cert.pem")],
                           capture_output=True, text=True, timeout=60)
    assert check.returncode != 0


def test_the_governance_is_sros2s_for_the_domain(keystore):
    doc = ElementTree.parse(keystore / "enclaves/governance.xml")
    rule = doc.find("domain_access_rules/domain_rule")
    assert rule is not None and rule.findtext("domains/id") == "23"
    for path, value in GOVERNANCE.items():
        assert rule.findtext(path) == value, path


def test_each_enclave_is_granted_its_part_and_denied_the_rest(keystore):
    ns = "rt/bayesprog"
    explorer, driver, viewer = "/bayesprog/explorer", "/bayesprog/driver", "/bayesprog/rviz"
    # only the driver may publish probes, only the explorer replies and maps
    assert may(keystore, driver, "publish", f"{ns}/probe")
    assert not may(keystore, explorer, "publish", f"{ns}/probe")
    assert not may(keystore, viewer, "publish", f"{ns}/probe")
    for topic in EXPLORER_OUT:
        assert may(keystore, explorer, "publish", f"{ns}/{topic}"), topic
        assert not may(keystore, driver, "publish", f"{ns}/{topic}"), topic
        assert not may(keystore, viewer, "publish", f"{ns}/{topic}"), topic
        assert may(keystore, driver, "subscribe", f"{ns}/{topic}"), topic
        assert may(keystore, viewer, "subscribe", f"{ns}/{topic}"), topic
    assert may(keystore, explorer, "subscribe", f"{ns}/probe")
    assert not may(keystore, driver, "subscribe", f"{ns}/probe")  # nobody reads a driver's lines
    assert not may(keystore, explorer, "publish", "rt/left/reply")  # another namespace
    for enclave in (explorer, driver, viewer):
        doc = ElementTree.parse(keystore / f"enclaves{enclave}/permissions.xml")
        entry = doc.find("permissions/grant")
        assert entry is not None and entry.get("name") == enclave
        assert entry.findtext("subject_name") == f"CN={enclave}"
        assert entry.findtext("default") == "DENY"
        assert {d.text for d in doc.iterfind(".//domains/id")} == {"23"}
        cert = x509.load_pem_x509_certificate(
            (keystore / f"enclaves{enclave}/cert.pem").read_bytes())
        assert entry.findtext("validity/not_before") == \
            cert.not_valid_before_utc.replace(tzinfo=None).isoformat()
        assert may(keystore, enclave, "publish", "rt/rosout")
        assert may(keystore, enclave, "publish", "ros_discovery_info")


def test_a_robot_added_later_keeps_the_ca_and_the_others_identities(keystore, tmp_path):
    copy = tmp_path / "keystore"
    shutil.copytree(keystore, copy, symlinks=True)
    before = {p: (copy / p).read_bytes() for p in ("public/ca.cert.pem",
                                                   "enclaves/bayesprog/explorer/cert.pem",
                                                   "enclaves/governance.p7s")}
    added = create(copy, "--enclaves", "/lab/arm_2", "--namespace", "/bayesprog")
    assert added.returncode == 0, added.stderr
    assert all((copy / p).read_bytes() == content for p, content in before.items())
    assert may(copy, "/lab/arm_2", "publish", "rt/bayesprog/probe")
    ca = x509.load_pem_x509_certificate((copy / "public/ca.cert.pem").read_bytes())
    x509.load_pem_x509_certificate((copy / "enclaves/lab/arm_2/cert.pem").read_bytes()) \
        .verify_directly_issued_by(ca)
    other = create(copy, "--enclaves", "/lab/arm_3", domain="40")
    assert other.returncode == 2 and "governs domain 23, not 40" in other.stderr


def test_the_namespaces_given_are_the_ones_granted(tmp_path):
    made = create(tmp_path / "ks", "--enclaves", "/lab/explorer", "/lab/hand",
                  "--explorer", "/lab/explorer", "--namespace", "/left", "--namespace", "/right")
    assert made.returncode == 0, made.stderr
    for side in ("left", "right"):
        assert may(tmp_path / "ks", "/lab/hand", "publish", f"rt/{side}/probe")
        assert may(tmp_path / "ks", "/lab/explorer", "publish", f"rt/{side}/reply")
        assert may(tmp_path / "ks", "/lab/explorer", "publish",
                   f"rr/{side}/bayesprog_explorer/get_parametersReply")
    assert not may(tmp_path / "ks", "/lab/hand", "publish", "rt/bayesprog/probe")


@pytest.mark.parametrize("args, expected", [
    (["--enclaves", "bayesprog/driver"], "expected an absolute name"),
    (["--enclaves", "/bayesprog/2nd"], "none starting with a digit"),
    (["--enclaves", "/a/driver", "--explorer", "/a/explorer"], "not among --enclaves"),
    (["--enclaves", "/a/driver", "--viewers", "/a/driver"], "also among --enclaves"),
    (["--enclaves", "/a/driver", "--domain", "999"], "from 0 to 232"),
    (["--enclaves", "/a/driver", "--namespace", "left"], "expected an absolute namespace"),
])
def test_bad_arguments_are_user_errors(tmp_path, args, expected):
    made = create(tmp_path / "ks", *args)
    assert made.returncode == 2 and expected in made.stderr, made.stderr
    assert "Traceback" not in made.stderr and len(made.stderr.strip().splitlines()) == 1


def test_a_folder_of_other_files_is_not_taken_for_a_keystore(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    made = create(tmp_path, "--enclaves", *ENCLAVES)
    assert made.returncode == 2 and "no keystore" in made.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_grant_knows_only_the_three_parts():
    with pytest.raises(ValueError, match="expected one of explorer, driver, viewer"):
        grant("robot")
