"""Zenoh access control for a machine's router, made from its manifest's ``[zenoh.access]``.

Where it is enforced: every service is a Zenoh peer that reaches its own machine's
router over plain TCP on loopback, and machines reach each other only router to
router over mutual TLS. So each router sees two kinds of link, and Zenoh's access
control tells them apart by the link itself:

- ``local``: a TCP link on the loopback interface, this machine's own processes
  (services, the CLI, the robot's ROS 2 nodes over rmw_zenoh). They may do anything:
  whoever runs code on a machine already owns it. "Anything" is ``**`` plus what
  ``**`` never matches, because ``@`` chunks are hermetic in Zenoh: the history
  topics' ``@adv`` keys, and for each ROS 2 domain the manifest's base speaks over
  rmw_zenoh its discovery (liveliness tokens, liveliness subscribers and the start-up
  liveliness query under ``@ros2_lv/<domain>/**``) and its transient-local topics'
  ``<domain>/**/@adv/**``. Where rmw_zenoh's peers and ours mesh directly over
  loopback (its default session: a peer with gossip) the router is not in their path;
  it is for every ROS 2 node in client mode and for whatever it relays.
- a remote machine: a TLS link whose client certificate (signed by the deployment's
  CA, checked by mutual TLS) has that machine's name as its common name. What it may
  send is its role's :class:`Grants` below; whatever else it sends is denied, and the
  router logs each denial (``... is unauthorized to Put (ingress) on <key>``, read by
  :mod:`common.acl_log`).

Everything else is denied (``default_permission: deny``): a link matching neither,
e.g. a certificate with an unknown common name, can do nothing.

The robot's router is the hub the Jetson and the base station link to, so it checks
what every remote machine sends where it comes in. The Jetson's and the base
station's routers link only to the hub, which relays the other machines' traffic
after checking it: they give it the role ``hub`` (anything under ``phenorover/``).

Who sends what, from :mod:`common.keys`: only the robot publishes velocity commands
(nav) and calls nav and the scanner (mission); missions are commanded and the planner
asked only by the base station and the robot (the robot's own CLI, and mission asking
for its plan); each machine publishes its own services' topics; everyone publishes
health, answers and sends pings, subscribes to anything under ``phenorover/`` and
asks who is alive; a machine declares liveliness tokens only under its own name
(``alive/<common name>/...``). The simulator's keys are granted to nobody.
:func:`router_acl` turns this into the ``access_control`` section of a Zenoh config.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterable
from typing import Any

from common import keys
from common.config import AccessConfig, Role

# every message type Zenoh's access control filters (zenoh 1.10)
MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
ALL = f"{keys.PREFIX}/**"
ALIVE = keys.ALIVE_ALL


def key_expr(key: str) -> str:
    """A key template as a key expression: each ``{placeholder}`` becomes ``*``."""
    return re.sub(r"\{[^}]*\}", "*", key)


@dataclasses.dataclass(frozen=True)
class Grants:
    """What a machine of one role may send into a router: ``publishes`` (put),
    ``calls`` (query), ``serves`` (declare a queryable and reply). Key expressions."""

    publishes: tuple[str, ...] = ()
    calls: tuple[str, ...] = ()
    serves: tuple[str, ...] = ()


def _scoped(key: str) -> tuple[str, ...]:
    """A key as a key expression, and as any robot's in a namespace (:mod:`common.keys`)."""
    both = (key_expr(key), key_expr(keys.in_namespace(key, "*")))
    return both[:1] if both[0] == both[1] else both


def _keys(*items: keys.Topic[Any] | keys.Rpc[Any, Any]) -> tuple[str, ...]:
    return tuple(e for i in items for e in _scoped(i.key))


# what every machine may send besides its role's grants: heartbeats, pings and the
# configurations services run with (a mission records them all)
EVERYONE = Grants(
    publishes=_keys(keys.HEALTH),
    calls=_keys(keys.PING, keys.CONFIG),
    serves=_keys(keys.PING, keys.CONFIG),
)

# History topics (common.keys.Topic.history) also travel under ``<key>/@adv/...``: the
# publisher's heartbeats, cache queryable and liveliness token (``@adv/pub``), the
# subscribers' tokens (``@adv/sub``). ``@adv`` is a verbatim chunk that ``**`` never
# matches, so these get rules of their own.
HISTORY = _keys(*(t for t in keys.ALL_TOPICS if t.history))


def adv(expr: str, side: str = "**") -> str:
    return f"{expr}/@adv/{side}" if side == "**" else f"{expr}/@adv/{side}/**"


def _history_rules(role: str, g: Grants) -> list[dict[str, Any]]:
    """A publisher of a history topic announces and serves its cache; every machine
    may subscribe to it: watch the publishers, ask their caches, announce itself."""
    own = tuple(h for h in HISTORY if h in g.publishes or ALL in g.publishes)
    pub_side = ["put", "declare_queryable", "reply", "liveliness_token"]
    sub_side = ["query", "declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"]
    rules = [
        _rule(f"{role}: history out", pub_side, tuple(adv(h, "pub") for h in own), "ingress"),
        _rule(f"{role}: history in", sub_side, tuple(adv(h) for h in HISTORY), "ingress"),
        _rule(
            f"{role}: history token",
            ["liveliness_token"],
            tuple(adv(h, "sub") for h in HISTORY),
            "ingress",
        ),
        _rule(f"{role}: history receive", list(MESSAGES), tuple(adv(h) for h in HISTORY), "egress"),
    ]
    return [r for r in rules if r["key_exprs"]]


ROLES: dict[Role, Grants] = {
    "robot": Grants(
        publishes=_keys(
            keys.GNSS_FIX,
            keys.GNSS_HEADING,
            keys.BASE_CMD_VEL,  # nav only
            keys.BASE_ESTOP,
            keys.BASE_ODOM,
            keys.BASE_SCAN,
            keys.BASE_IMU,
            keys.BASE_STATUS,
            keys.BASE_BATTERY,
            keys.NAV_POSE,
            keys.NAV_PROGRESS,
            keys.MISSION_STATE,
            keys.MISSION_EVENT,
            keys.MISSION_PLAN,
        ),
        # mission drives nav and the scanner and asks the planner; the robot's CLI
        # commands missions; robots sharing a field ask each other's lane reservations
        calls=_keys(
            keys.NAV_CMD, keys.SCANNER_CMD, keys.PLANNER_PLAN, keys.MISSION_CMD, keys.FLEET_LANES
        ),
        serves=_keys(keys.NAV_CMD, keys.MISSION_CMD, keys.FLEET_LANES),
    ),
    "jetson": Grants(publishes=_keys(keys.SCANNER_STATUS), serves=_keys(keys.SCANNER_CMD)),
    "basestation": Grants(
        calls=_keys(keys.MISSION_CMD, keys.PLANNER_PLAN), serves=_keys(keys.PLANNER_PLAN)
    ),
    # the hub relays every machine's traffic, checked where it came in
    "hub": Grants(publishes=(ALL,), calls=(ALL,), serves=(ALL,)),
}

# keys no role is granted: only the simulated deployment (no access control) uses them
SIMULATION_ONLY = _keys(
    keys.SIM_CLOCK,
    keys.SIM_ACK,
    keys.SIM_TRUTH,
    keys.SIM_ANTENNAS,
    keys.SIM_WHEELS,
    keys.SIM_ENCODERS,
    keys.SIM_LIDAR,
    keys.SIM_IMU,
    keys.SIM_BATTERY,
    keys.SIM_RENDER,
    keys.SIM_RUN,
)


def _rule(rid: str, messages: list[str], exprs: tuple[str, ...], flow: str) -> dict[str, Any]:
    return {
        "id": rid,
        "permission": "allow",
        "flows": [flow],
        "messages": messages,
        "key_exprs": list(exprs),
    }


def role_rules(role: Role) -> list[dict[str, Any]]:
    """The allow rules for a remote machine of ``role`` (ids prefixed by the role)."""
    g, e = ROLES[role], EVERYONE
    rules = [
        # whatever this router forwards to a remote machine: it was checked coming in
        _rule(f"{role}: receive", list(MESSAGES), (ALL,), "egress"),
        _rule(f"{role}: publish", ["put"], g.publishes + e.publishes, "ingress"),
        _rule(f"{role}: call", ["query"], g.calls + e.calls, "ingress"),
        _rule(f"{role}: serve", ["declare_queryable", "reply"], g.serves + e.serves, "ingress"),
        _rule(f"{role}: listen", ["declare_subscriber"], (ALL,), "ingress"),
        _rule(
            f"{role}: watch liveliness",
            ["declare_liveliness_subscriber", "liveliness_query"],
            (ALIVE,),
            "ingress",
        ),
    ]
    return [r for r in rules if r["key_exprs"]] + _history_rules(role, g)


def alive_rule(cn: str, role: Role) -> dict[str, Any]:
    """A machine declares liveliness tokens for its own services only
    (``alive/<machine>/...``, the machine named by its certificate); the hub relays
    every machine's."""
    where = ALIVE if role == "hub" else keys.ALIVE.split("{machine}")[0] + f"{cn}/**"
    return _rule(f"{cn}: alive", ["liveliness_token"], (where,), "ingress")


def ros2_exprs(domain: int) -> tuple[str, str]:
    """What rmw_zenoh uses of ROS 2 domain ``domain`` that ``**`` does not match:
    discovery, and the transient-local topics' advanced publisher keys (its data keys
    ``<domain>/<topic>/<type>/<hash>`` are under ``**``)."""
    return f"@ros2_lv/{domain}/**", f"{domain}/**/@adv/**"


def router_acl(access: AccessConfig, ros2_domains: Iterable[int] = ()) -> dict[str, Any]:
    """The ``access_control`` section for a router: default deny, this machine's own
    loopback TCP links allowed everything (with rmw_zenoh's keys of ``ros2_domains``),
    each remote certificate common name in ``access.remotes`` allowed its role's
    grants; no remote machine is allowed any ROS 2 key."""
    local = ("**", *map(adv, HISTORY))
    for d in sorted(set(ros2_domains)):
        local += ros2_exprs(d)
    rules: list[dict[str, Any]] = [
        _rule("local: anything", list(MESSAGES), local, "ingress"),
        _rule("local: receive", list(MESSAGES), local, "egress"),
    ]
    subjects: list[dict[str, Any]] = [
        {"id": "local", "interfaces": [access.loopback], "link_protocols": ["tcp"]}
    ]
    policies: list[dict[str, Any]] = [
        {"id": "local", "rules": ["local: anything", "local: receive"], "subjects": ["local"]}
    ]
    for role in sorted(set(access.remotes.values())):
        rules += role_rules(role)
    for cn, role in sorted(access.remotes.items()):
        sid = f"machine {cn}"
        subjects.append({"id": sid, "cert_common_names": [cn], "link_protocols": ["tls"]})
        rules.append(alive_rule(cn, role))
        ids = [r["id"] for r in role_rules(role)] + [f"{cn}: alive"]
        policies.append({"id": f"{cn} as {role}", "rules": ids, "subjects": [sid]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def may_send(role: Role, message: str, key: str) -> bool:
    """Whether a remote machine of ``role`` may send ``message`` (put, query, reply,
    declare_queryable) on the concrete ``key``: the policy as a function, for docs and
    tests; the router itself decides with Zenoh's key-expression matching."""
    g = ROLES[role]
    exprs = {
        "put": g.publishes + EVERYONE.publishes,
        "query": g.calls + EVERYONE.calls,
        "reply": g.serves + EVERYONE.serves,
        "declare_queryable": g.serves + EVERYONE.serves,
    }[message]
    return any(_matches(e, key) for e in exprs)


def _matches(expr: str, key: str) -> bool:
    pattern = "^" + re.escape(expr).replace(r"\*\*", ".*").replace(r"\*", "[^/]+") + "$"
    return re.match(pattern, key) is not None
