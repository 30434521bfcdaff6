"""TLS and mutual TLS on the gRPC port, with certificates made for the test
(openssl, a throwaway CA valid for a day): the right CA connects, a wrong CA
or a plaintext client fails cleanly, mutual TLS refuses clients without a
certificate of its CA; the CLI connects with --tls-ca; bad files stop the
server at start with what is wrong."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import filigree

DATA = Path(__file__).resolve().parent.parent / "data"


def openssl(*args, cwd):
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def make_ca(d: Path, name: str) -> None:
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1",
            "-subj", f"/CN={name}", "-keyout", f"{name}.key", "-out", f"{name}.pem", cwd=d)


def make_cert(d: Path, name: str, ca: str, extensions: str) -> None:
    openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-subj", f"/CN={name}",
            "-keyout", f"{name}.key", "-out", f"{name}.csr", cwd=d)
    (d / f"{name}.ext").write_text(extensions + "\n")
    openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key", "-CAcreateserial",
            "-days", "1", "-out", f"{name}.pem", "-extfile", f"{name}.ext", cwd=d)


@pytest.fixture(scope="module")
def pki():
    d = Path(tempfile.mkdtemp(prefix="filigree_tls_"))
    make_ca(d, "ca")
    make_ca(d, "other_ca")
    make_cert(d, "server", "ca", "subjectAltName=IP:127.0.0.1,DNS:localhost")
    make_cert(d, "client", "ca", "extendedKeyUsage=clientAuth")
    make_cert(d, "stranger", "other_ca", "extendedKeyUsage=clientAuth")
    yield d
    shutil.rmtree(d, ignore_errors=True)


class TlsServer:
    def __init__(self, pki: Path, mutual: bool) -> None:
        self.data_dir = tempfile.mkdtemp(prefix="filigree_tls_server_")
        args = [os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--data-dir", self.data_dir,
                "--log-level", "warn", "--tls-cert", str(pki / "server.pem"), "--tls-key", str(pki / "server.key")]
        if mutual:
            args += ["--tls-client-ca", str(pki / "ca.pem")]
        self.process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()
        assert line.startswith("listening on "), line + self.process.stderr.read()
        self.address = line.split()[-1]

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=60)
        shutil.rmtree(self.data_dir, ignore_errors=True)


@pytest.fixture(scope="module")
def tls_server(pki):
    s = TlsServer(pki, mutual=False)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def mtls_server(pki):
    s = TlsServer(pki, mutual=True)
    yield s
    s.stop()


def upload_and_drive(client: filigree.Client) -> None:
    with client.create_session(DATA / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150)) as s:
        with s.drive("tls") as driver:
            frame = driver.wait_for_pose(driver.send(s.base_positions + np.float32(0.01)), 30)
            assert frame.pose_id == 1


def test_tls_with_the_servers_ca(tls_server, pki):
    with filigree.Client(tls_server.address, root_certificates=(pki / "ca.pem").read_bytes()) as client:
        upload_and_drive(client)


def test_a_wrong_ca_or_plaintext_fails_cleanly(tls_server, pki):
    with filigree.Client(tls_server.address, root_certificates=(pki / "other_ca.pem").read_bytes()) as client:
        with pytest.raises(filigree.Unavailable):
            client.join("0123456789abcdef0123", "token")
    with filigree.Client(tls_server.address) as plaintext:
        with pytest.raises(filigree.Unavailable):
            plaintext.join("0123456789abcdef0123", "token")
    assert tls_server.process.poll() is None


def test_mutual_tls_needs_a_client_certificate_of_its_ca(mtls_server, pki):
    ca = (pki / "ca.pem").read_bytes()
    with filigree.Client(mtls_server.address, root_certificates=ca) as anonymous:
        with pytest.raises(filigree.Unavailable):
            anonymous.join("0123456789abcdef0123", "token")
    with filigree.Client(mtls_server.address, root_certificates=ca, certificate_chain=(pki / "stranger.pem").read_bytes(),
                         private_key=(pki / "stranger.key").read_bytes()) as stranger:
        with pytest.raises(filigree.Unavailable):
            stranger.join("0123456789abcdef0123", "token")
    with filigree.Client(mtls_server.address, root_certificates=ca, certificate_chain=(pki / "client.pem").read_bytes(),
                         private_key=(pki / "client.key").read_bytes()) as client:
        upload_and_drive(client)


def test_the_cli_over_tls(tls_server, mtls_server, pki):
    cli = os.environ["FILIGREE_CLI"]
    ok = subprocess.run([cli, "health", "--server", tls_server.address, "--tls-ca", str(pki / "ca.pem")],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    plain = subprocess.run([cli, "health", "--server", tls_server.address], capture_output=True, text=True, timeout=60)
    assert plain.returncode != 0
    mutual = subprocess.run([cli, "sessions", "--server", mtls_server.address, "--tls-ca", str(pki / "ca.pem"),
                             "--tls-cert", str(pki / "client.pem"), "--tls-key", str(pki / "client.key")],
                            capture_output=True, text=True, timeout=60)
    assert mutual.returncode == 0, mutual.stdout + mutual.stderr


def test_bad_tls_files_stop_the_server_saying_which(pki):
    missing = subprocess.run([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--tls-cert",
                              str(pki / "server.pem"), "--tls-key", str(pki / "no_such.key")],
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 1 and "no_such.key" in missing.stderr
    lone = subprocess.run([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--tls-cert",
                           str(pki / "server.pem")], capture_output=True, text=True, timeout=60)
    assert lone.returncode == 1 and "--tls-key" in lone.stderr
    not_pem = subprocess.run([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--tls-cert",
                              str(pki / "server.ext"), "--tls-key", str(pki / "server.key")],
                             capture_output=True, text=True, timeout=60)
    assert not_pem.returncode == 1 and "PEM" in not_pem.stderr


def test_plaintext_beyond_loopback_needs_insecure():
    """Secure by default: the refusal comes before anything listens."""
    server = os.environ["FILIGREE_SERVER"]
    for args, flag in ((["--listen", "0.0.0.0:0"], "--listen"), (["--listen", "[::]:0"], "--listen"),
                       (["--listen", "127.0.0.1:0", "--http", "0.0.0.0:0"], "--http")):
        refused = subprocess.run([server, *args], capture_output=True, text=True, timeout=60)
        assert refused.returncode == 1, (args, refused.stdout)
        assert flag in refused.stderr and "--insecure" in refused.stderr, refused.stderr
        assert "listening on" not in refused.stdout


def test_sighup_renews_the_https_certificate_without_dropping_sessions(pki):
    """The browser port's certificate is replaced on disk, SIGHUP: the next
    HTTPS connection gets the new certificate, the session and a connection
    opened before go on."""
    import signal
    import socket
    import ssl

    d = Path(tempfile.mkdtemp(prefix="filigree_sighup_", dir=pki))
    for name in ("server.pem", "server.key"):
        shutil.copy(pki / name, d / name)
    server = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0",
                               "--log-level", "info", "--tls-cert", str(d / "server.pem"), "--tls-key",
                               str(d / "server.key")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        grpc_address = server.stdout.readline().split()[-1]
        http_host, http_port = server.stdout.readline().split()[-1].rsplit(":", 1)
        context = ssl.create_default_context(cafile=str(pki / "ca.pem"))

        def serial() -> int:
            with socket.create_connection((http_host, int(http_port)), timeout=30) as raw, \
                    context.wrap_socket(raw, server_hostname="localhost") as tls:
                return int(tls.getpeercert()["serialNumber"], 16)

        before = serial()
        client = filigree.Client(grpc_address, root_certificates=(pki / "ca.pem").read_bytes())
        session = client.create_session(DATA / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150))
        kept = context.wrap_socket(socket.create_connection((http_host, int(http_port)), timeout=30),
                                   server_hostname="localhost")
        # A renewal: a new certificate of the same CA, written over the old files.
        for suffix in ("pem", "key"):
            shutil.copy(pki / f"ca.{suffix}", d / f"ca.{suffix}")
        make_cert(d, "server", "ca", "subjectAltName=IP:127.0.0.1,DNS:localhost")
        server.send_signal(signal.SIGHUP)
        for line in server.stderr:  # the reload is in force before this line is logged
            assert "reload_failed" not in line, line
            if "event=https_certificate_reloaded" in line:
                break
        after = serial()
        assert after != before
        # The connection opened before still works, and so does the session.
        kept.sendall(f"GET / HTTP/1.1\r\nHost: {http_host}\r\n\r\n".encode())
        assert kept.recv(12).startswith(b"HTTP/1.1")
        kept.close()
        with session.drive("after-renewal") as driver:
            frame = driver.wait_for_pose(driver.send(session.base_positions), 30)
            assert frame.pose_id >= 1
        session.free()
        client.close()
    finally:
        server.terminate()
        server.wait(timeout=60)
