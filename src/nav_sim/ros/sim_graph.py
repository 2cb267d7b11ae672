"""Which nodes act as the sim in a namespace, from the ROS graph (one sim per namespace).

Two sims in one namespace both step on every ``cmd_vel`` and both answer ``reset``: a client
would get observations and rewards from two worlds.  The client checks before it attaches and at
each reset; the sim checks when asked to reset (it has long discovered its neighbours, while a
client that has just started may not have yet).
"""

from __future__ import annotations

from collections.abc import Collection

from rclpy.node import Node

from nav_sim.errors import SimConflictError
from nav_sim.interface import CMD_VEL_TOPIC, IMAGE_TOPIC, RESET_SERVICE, cmd_vel_type, full_name

#: how a refusal for this reason begins (a reset response message, an exception message)
CONFLICT = 'several sims in one namespace'
UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'  # what the graph reports before a node's name is known


def sim_count(node: Node) -> int:
    """Count the camera publishers and reset servers in ``node``'s namespace (the larger)."""
    return max(node.count_publishers(node.resolve_topic_name(IMAGE_TOPIC)),
               node.count_services(node.resolve_service_name(RESET_SERVICE)))


def sim_nodes(node: Node) -> list[str]:
    """Name the nodes that publish the camera or serve ``reset`` in ``node``'s namespace.

    One entry per publisher: two sims started under the same node name appear twice.
    """
    camera = node.resolve_topic_name(IMAGE_TOPIC)
    names = [full_name(info.node_namespace, info.node_name)
             for info in node.get_publishers_info_by_topic(camera)]
    reset = node.resolve_service_name(RESET_SERVICE)
    if node.count_services(reset):
        for name, namespace in sorted(set(node.get_node_names_and_namespaces())):
            try:
                services = node.get_service_names_and_types_by_node(name, namespace)
            except Exception:  # noqa: BLE001 - the node left the graph meanwhile
                continue
            full = full_name(namespace, name)
            if full not in names and any(service == reset for service, _ in services):
                names.append(full)
    return names


def conflict_message(node: Node, names: list[str]) -> str:
    """Say that several sims share ``node``'s namespace, naming them, and what to do."""
    count = max(sim_count(node), len(names))
    return (f"{CONFLICT}: {count} nodes in namespace '{node.get_namespace()}' publish "
            f"{IMAGE_TOPIC} or serve {RESET_SERVICE} ({', '.join(names)}); their worlds would "
            'mix: stop all but one sim, or give each its own namespace '
            '(`--ros-args -r __ns:=/NAME`)')


def cmd_vel_mismatch(node: Node, stamped: bool,
                     among: Collection[str] | None = None) -> str | None:
    """Say which node takes ``cmd_vel`` as another type than this setting's, or None.

    ROS 2 matches a publisher to a subscriber only where their types agree, so a mismatch is a
    silence, not an error: nothing would step the sim.  The graph still shows every endpoint's
    type, and this names the first subscriber (of the nodes ``among``, or any) that differs.
    """
    topic = node.resolve_topic_name(CMD_VEL_TOPIC)
    mine = cmd_vel_type(stamped)
    infos = node.get_subscriptions_info_by_topic(topic)
    own = node.get_fully_qualified_name()
    for info in infos:
        name = full_name(info.node_namespace, info.node_name)
        if UNKNOWN_NODE in name:  # its name comes later: name it then
            continue
        if info.topic_type != mine and name != own and (among is None or name in among):
            return (f'{name} takes {topic} as {info.topic_type}, but {own} uses {mine} '
                    f'(cmd_vel_stamped {str(stamped).lower()}): give both the same '
                    'cmd_vel_stamped setting')
    return None


def refuse_cmd_vel_mismatch(node: Node, stamped: bool, where: str) -> None:
    """Raise SimConflictError if the sim in ``node``'s namespace takes the other cmd_vel type."""
    problem = cmd_vel_mismatch(node, stamped, among=sim_nodes(node))
    if problem:
        raise SimConflictError(f'nav_sim in {where}: {problem}')
