"""An authenticated, access-controlled bus with Zenoh's own mechanisms (docs/security.md).

`policy`: who may do what (pure), and the router's ACL from it; `secrets`: a run's
passwords, user list and ACL on disk; `denials`: the router's refusals as log events.
"""

from cbdi.security.policy import Grant, acl_config, grants, user_of
from cbdi.security.secrets import (
    CREDENTIALS_ENV,
    Credentials,
    RunSecrets,
    create_secrets,
    discover,
    ensure_secrets,
    read_credentials,
    run_dir,
)

__all__ = [
    "CREDENTIALS_ENV",
    "Credentials",
    "Grant",
    "RunSecrets",
    "acl_config",
    "create_secrets",
    "discover",
    "ensure_secrets",
    "grants",
    "read_credentials",
    "run_dir",
    "user_of",
]
