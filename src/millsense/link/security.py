"""Security of the OPC UA link (issue 18 item 3; decision 1802).

- **Certificates**, generated on first use (RSA 2048, self-signed, one year, the application
  URI in the subject alternative name) in the link's configuration folder, never in the
  repository: ``$MILLSENSE_OPCUA_DIR`` or ``--pki``, else ``$XDG_CONFIG_HOME/millsense/opcua``
  (``~/.config/millsense/opcua``). Layout: ``server/`` and ``client/`` (``cert.der``,
  ``key.pem``), ``trusted/clients/`` (client certificates the server accepts) and
  ``trusted/servers/`` (server certificates the client accepts); ``millsense opcua-trust``
  copies a certificate there.
- **Users** in ``users.toml`` of that folder: name, role (``operator``: may write the
  overrides and call the feed hold; ``viewer``: may read and subscribe) and a PBKDF2-SHA256
  hash of the password with its salt (``millsense opcua-user``); no password is stored.
- **Roles on the wire**: :class:`RoleRuleset` refuses a Write request unless the session's
  user is an operator, and a Call of anything but the data-flow methods (Step, Resend) unless
  the user is an operator; each refusal is logged.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import os
import secrets
import shutil
import socket
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from millsense.core.errors import ConfigError

log = logging.getLogger("millsense.link")

ENV_DIR = "MILLSENSE_OPCUA_DIR"
ROLES = ("operator", "viewer")
PBKDF2_ITERATIONS = 200_000
SERVER_URI = "urn:millsense:virtual-machine:server"
CLIENT_URI = "urn:millsense:client"


def pki_dir(override: str | Path | None = None) -> Path:
    """The link's configuration folder (see the module docstring)."""
    if override is not None:
        return Path(override)
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "millsense" / "opcua"


def status_name(exc: BaseException) -> str:
    """The OPC UA status code name of an asyncua error (its class name if it has none)."""
    code = getattr(exc, "code", None)
    if code is None:
        return type(exc).__name__
    from asyncua import ua

    return next((k for k, v in vars(ua.StatusCodes).items() if v == code), str(code))


class UntrustedServer(ConfigError):
    """The server's certificate is not among the trusted ones."""


@dataclass(frozen=True)
class Identity:
    """A certificate (DER) and its private key (PEM)."""

    cert: Path
    key: Path


async def ensure_identity(pki: Path, role: str) -> Identity:
    """The ``role`` (``server`` or ``client``) certificate of ``pki``, made if missing or
    expired (asyncua's self-signed generator: key usage for signing and encryption)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    folder = pki / role
    folder.mkdir(parents=True, exist_ok=True)
    (pki / "trusted" / "clients").mkdir(parents=True, exist_ok=True)
    (pki / "trusted" / "servers").mkdir(parents=True, exist_ok=True)
    ident = Identity(folder / "cert.der", folder / "key.pem")
    uri = SERVER_URI if role == "server" else CLIENT_URI
    use = [ExtendedKeyUsageOID.SERVER_AUTH if role == "server" else ExtendedKeyUsageOID.CLIENT_AUTH]
    fresh = not ident.key.exists()
    await setup_self_signed_certificate(
        ident.key, ident.cert, uri, socket.gethostname(), use,
        {"countryName": "CH", "organizationName": "millsense", "commonName": f"millsense {role}"},
    )  # fmt: skip
    if fresh:
        os.chmod(ident.key, 0o600)
        log.warning("%s certificate generated in %s", role, folder)
    return ident


def trust(pki: Path, cert: Path, kind: str) -> Path:
    """Copy ``cert`` (DER) into ``trusted/<kind>s/`` (``kind``: client or server)."""
    if kind not in ("client", "server"):
        raise ConfigError(f"opcua-trust: --kind client or server, got {kind!r}")
    if not cert.is_file():
        raise ConfigError(f"{cert}: no such certificate")
    dest = pki / "trusted" / f"{kind}s"
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / cert.name if cert.name != "cert.der" else dest / f"{cert.parent.name}.der"
    shutil.copyfile(cert, target)
    return target


# ---------------------------------------------------------------------------- users
def _hash(password: str, salt: bytes, iterations: int) -> str:
    return hashlib.pbkdf2_hmac("sha256", password.encode(), salt, iterations).hex()


def add_user(path: Path, name: str, password: str, role: str) -> None:
    """Add or replace ``name`` in the users file ``path`` with a salted PBKDF2 hash."""
    if role not in ROLES:
        raise ConfigError(f"opcua-user: --role one of {', '.join(ROLES)}, got {role!r}")
    if not name or not name.replace("-", "").replace("_", "").isalnum():
        raise ConfigError(f"opcua-user: user name must be letters, digits, - or _, got {name!r}")
    if len(password) < 8:
        raise ConfigError("opcua-user: the password must have at least 8 characters")
    users = _read_users(path) if path.exists() else {}
    salt = secrets.token_bytes(16)
    users[name] = {"role": role, "salt": salt.hex(), "iterations": PBKDF2_ITERATIONS,
                   "pbkdf2_sha256": _hash(password, salt, PBKDF2_ITERATIONS)}  # fmt: skip
    lines = ["# millsense OPC UA users (millsense opcua-user); passwords are not stored", ""]
    for n, u in sorted(users.items()):
        lines += [f"[users.{n}]", f'role = "{u["role"]}"', f'salt = "{u["salt"]}"',
                  f"iterations = {int(u['iterations'])}",
                  f'pbkdf2_sha256 = "{u["pbkdf2_sha256"]}"', ""]  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    os.chmod(tmp, 0o600)
    tmp.replace(path)


def _read_users(path: Path) -> dict[str, dict[str, Any]]:
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the users file ({exc})") from None
    users = raw.get("users", {})
    for n, u in users.items():
        if u.get("role") not in ROLES or not isinstance(u.get("pbkdf2_sha256"), str):
            raise ConfigError(f"{path}: users.{n}: role ({'/'.join(ROLES)}) and hash needed")
    return dict(users)


class Users:
    """The users file as the server's user manager (asyncua ``get_user``): a session with a
    wrong name or password, or anonymous where it is not allowed, is refused and logged."""

    def __init__(self, path: Path, allow_anonymous: bool = False) -> None:
        self.path = path
        self.users = _read_users(path) if path.exists() else {}
        self.allow_anonymous = allow_anonymous

    def role(self, name: str, password: str) -> str | None:
        u = self.users.get(name)
        if u is None:
            return None
        got = _hash(password, bytes.fromhex(u["salt"]), int(u.get("iterations", PBKDF2_ITERATIONS)))
        return str(u["role"]) if hmac.compare_digest(got, u["pbkdf2_sha256"]) else None

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:  # fmt: skip
        from asyncua.crypto.permission_rules import User, UserRole

        if username is None:
            if self.allow_anonymous:
                return User(role=UserRole.Anonymous, name="anonymous")
            log.warning("refused: anonymous session (start the server with --allow-anonymous)")
            return None
        role = self.role(username, password or "")
        if role is None:
            log.warning("refused: login of user %r (unknown user or wrong password)", username)
            return None
        log.info("session of user %r (%s)", username, role)
        return User(role=UserRole.User, name=f"{role}:{username}")


def user_role(user: Any) -> str:
    """``operator``, ``viewer`` or ``anonymous`` of an asyncua session user."""
    name = getattr(user, "name", None) or ""
    return name.split(":", 1)[0] if ":" in name else "anonymous"


class RoleRuleset:
    """Request permissions by role (asyncua ``PermissionRuleset``): everybody with a session
    reads, browses and subscribes; only an operator writes (the overrides) or calls a method
    other than ``data_methods`` (the feed hold). Refusals are logged with the user."""

    def __init__(self, data_methods: set[Any]) -> None:
        from asyncua import ua
        from asyncua.crypto.permission_rules import USER_TYPES

        def nid(i: int) -> Any:
            return ua.NodeId(ua.Int32(i))

        self.data_methods = data_methods
        self.write = nid(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
        self.call = nid(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
        self.read_types = {nid(t) for t in USER_TYPES} - {self.write, self.call}
        self.refusals = 0

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        from asyncua import ua
        from asyncua.ua.ua_binary import struct_from_binary

        role = user_role(user)
        if action_type_id in self.read_types:
            return True
        if role == "operator" and action_type_id in (self.write, self.call):
            return True
        if action_type_id == self.call:
            params = struct_from_binary(ua.CallParameters, body.copy())
            if all(m.MethodId in self.data_methods for m in params.MethodsToCall):
                return True
        what = "write" if action_type_id == self.write else "call"
        self.refusals += 1
        log.warning("refused: %s by %s (%s): overrides and the feed hold need an operator",
                    what, getattr(user, "name", None) or "anonymous", role)  # fmt: skip
        return False
