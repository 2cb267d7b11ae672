"""Which nodes act as the sim in a namespace, from the ROS graph (one sim per namespace).

Two sims in one namespace both step on every ``cmd_vel`` and both answer ``reset``: a client
would get observations and rewards from two worlds.  The client checks before it attaches and at
each reset; the sim checks when asked to reset (it has long discovered its neighbours, while a
client that has just started may not have yet).
"""

from __future__ import annotations

from rclpy.node import Node

from nav_sim.interface import IMAGE_TOPIC, RESET_SERVICE

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
    names = [_full_name(info.node_namespace, info.node_name)
             for info in node.get_publishers_info_by_topic(camera)]
    reset = node.resolve_service_name(RESET_SERVICE)
    if node.count_services(reset):
        for name, namespace in sorted(set(node.get_node_names_and_namespaces())):
            try:
                services = node.get_service_names_and_types_by_node(name, namespace)
            except Exception:  # noqa: BLE001 - the node left the graph meanwhile
                continue
            full = _full_name(namespace, name)
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


def _full_name(namespace: str, name: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"
