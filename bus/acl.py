"""The access-control table of the router: who may put, subscribe to, hold tokens on and watch which keys
(default deny), and the zenoh ``access_control`` section made of it (docs/security.md). No zenoh import: the
router (:mod:`auv_swarm.orchestrator.mission.router`) and :mod:`.zbus` apply it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from auv_swarm.contract import wire
from auv_swarm.contract.params import MAX_AGENTS, agent_user


@dataclass(frozen=True)
class Role:
    """What one zenoh user may do: keys it may put on, subscribe to, hold liveliness tokens on, and watch."""

    user: str
    publish: tuple[str, ...] = ()
    subscribe: tuple[str, ...] = ()
    tokens: tuple[str, ...] = ()
    watch: tuple[str, ...] = ()


def acl_roles(agents: int = MAX_AGENTS, prefix: str = wire.PREFIX) -> list[Role]:
    """The access-control table: one :class:`Role` per user; anything not listed is denied.

    An AUV may only publish its own tx/cmd/telemetry, hold its own liveliness
    tokens (``alive/auv/<id>/<session>``, one per session) and subscribe to its own rx, sensor, nav, the clock and the world
    events (and, under the centralised method, its own plan from the central planner), and
    watch the world's token (to end with the mission).
    The world also hears every AUV's frames and telemetry, for the sender's session only (``world.sessions``).
    The orchestrator computes the metrics and records the run: it reads truth,
    telemetry, the channel's stats and packet log, the world events, and the bearings
    taken and the frames delivered (for the run's bearing table); it publishes
    only its confirmation of the faults it injected (``orchestrator/faults``), which only
    the world reads. The recorder reads everything and publishes nothing. The central
    planner (centralised MPC only) reads the clock and every AUV's navigation and bearing,
    outside the acoustic channel, and publishes each AUV's plan, which only that AUV reads.
    """
    alive = wire.all_liveliness(prefix)
    auv_any = f"{prefix}/auv/*"
    roles = [
        Role(
            "world",
            publish=(
                wire.clock(prefix),
                wire.truth(prefix),
                wire.world_events(prefix),
                f"{auv_any}/nav",
                f"{auv_any}/sensor",
                wire.channel_tick(prefix),
            ),
            subscribe=(
                wire.all_commands(prefix),
                wire.all_modem_tx(prefix),
                wire.all_telemetry(prefix),
                wire.channel_done(prefix),
                wire.channel_stats(prefix),
                wire.channel_events(prefix),
                wire.faults_injected(prefix),
            ),
            tokens=(wire.liveliness_component("world", prefix),),
            watch=(alive,),
        ),
        Role(
            "channel",
            publish=(
                wire.all_modem_rx(prefix),
                wire.channel_done(prefix),
                wire.channel_stats(prefix),
                wire.channel_events(prefix),
            ),
            subscribe=(
                wire.all_modem_tx(prefix),
                wire.channel_tick(prefix),
                wire.clock(prefix),
                wire.world_events(prefix),
            ),
            tokens=(wire.liveliness_component("channel", prefix),),
            watch=(alive,),
        ),
        Role(
            "recorder",
            subscribe=(f"{prefix}/**",),
            tokens=(wire.liveliness_component("recorder", prefix),),
            watch=(alive,),
        ),
        Role(
            "orchestrator",
            publish=(wire.faults_injected(prefix),),
            subscribe=(
                wire.truth(prefix),
                wire.world_events(prefix),
                wire.all_telemetry(prefix),
                wire.channel_stats(prefix),
                wire.channel_events(prefix),
                wire.all_sensors(prefix),
                wire.all_modem_rx(prefix),
            ),
            tokens=(wire.liveliness_component("orchestrator", prefix),),
            watch=(alive,),
        ),
        Role(
            "central",
            publish=(wire.all_central_plans(prefix),),
            subscribe=(wire.clock(prefix), f"{auv_any}/nav", f"{auv_any}/sensor", wire.world_events(prefix)),
            tokens=(wire.liveliness_component("central", prefix),),
            watch=(wire.liveliness_component("world", prefix),),
        ),
    ]
    for n in range(agents):
        roles.append(
            Role(
                agent_user(n),
                publish=(wire.modem_tx(n, prefix), wire.command(n, prefix), wire.telemetry(n, prefix)),
                subscribe=(
                    wire.modem_rx(n, prefix),
                    wire.sensor(n, prefix),
                    wire.nav(n, prefix),
                    wire.clock(prefix),
                    wire.world_events(prefix),
                    wire.central_plan(n, prefix),
                ),
                tokens=(f"{wire.liveliness(n, prefix)}/*",),
                watch=(wire.liveliness_component("world", prefix),),
            )
        )
    return roles


def access_control(roles: list[Role], prefix: str = wire.PREFIX, subject: str = "usernames") -> dict[str, Any]:
    """The zenoh ``access_control`` section for ``roles`` (router side, default deny).

    ``subject`` is what names a role's holder: ``usernames`` (its usrpwd login) or ``cert_common_names`` (the
    common name of its TLS certificate, checked by the router's mutual TLS).

    Per user: ``put`` ingress on its publish keys, and (for a user that publishes)
    ``declare_subscriber`` egress on ``<prefix>/**``: zenoh clients filter
    publications on the writer side by the subscriber declarations they hear of,
    so a publisher that is never told of a subscriber stops sending after its
    first few puts (measured with zenoh 1.10). ``declare_subscriber`` ingress
    and ``put`` egress on its subscribe keys (so a message reaches a client only on
    keys it may read); ``liveliness_token`` ingress on its token keys;
    ``declare_liveliness_subscriber`` ingress and ``liveliness_token`` egress on its
    watched keys (enough for a liveliness subscriber with history; liveliness
    queries are not allowed). A rule matches only
    when its key expression includes the message's (a subscription to ``a/**`` is
    not allowed by a rule on ``a/b``).
    """
    if subject not in ("usernames", "cert_common_names"):
        raise ValueError(f"subject must be usernames or cert_common_names, got {subject!r}")
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def rule(rule_id: str, messages: list[str], flow: str, keys: tuple[str, ...]) -> str | None:
        if not keys:
            return None
        rules.append(
            {"id": rule_id, "messages": messages, "flows": [flow], "permission": "allow", "key_exprs": list(keys)}
        )
        return rule_id

    for role in roles:
        u = role.user
        ids = [
            rule(f"{u}/put", ["put"], "ingress", role.publish),
            rule(f"{u}/matching", ["declare_subscriber"], "egress", (f"{prefix}/**",) if role.publish else ()),
            rule(f"{u}/subscribe", ["declare_subscriber"], "ingress", role.subscribe),
            rule(f"{u}/receive", ["put"], "egress", role.subscribe),
            rule(f"{u}/token", ["liveliness_token"], "ingress", role.tokens),
            rule(f"{u}/watch", ["declare_liveliness_subscriber"], "ingress", role.watch),
            rule(f"{u}/watch-receive", ["liveliness_token"], "egress", role.watch),
        ]
        subjects.append({"id": u, subject: [u]})
        policies.append({"id": f"{u}-policy", "rules": [i for i in ids if i], "subjects": [u]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}
