"""ROS parameters of a node from a settings dataclass: declared, typed, converted (rclpy only).

The one way visnav's nodes (``sim_node``, ``policy_node``) take their parameters: one parameter
per dataclass field (:func:`nav_sim.core.config.setting`), described by the field's help text,
read once into the frozen dataclass.  A value of the wrong type in a params file or ``-p`` is a
:class:`nav_sim.errors.ConfigError` naming the parameter and its type (the nodes print it as one
line and exit with code 2); an unknown name (a typo) is a warning naming the closest known one.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable, Collection, Mapping
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from nav_sim.core.config import convert
from nav_sim.errors import ConfigError, VisnavError


def declare_settings(node: Node, config_type: type, dynamic: Collection[str] = (),
                     defaults: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Declare a parameter per field of ``config_type``; return the values (given or default).

    Fields not in ``dynamic`` are read-only.  A parameter not given takes its value from
    ``defaults`` (e.g. the world's settings), else the field's default.  A given value (params
    file, ``-p``) is converted as :func:`given` says.
    """
    values = {}
    for field in dataclasses.fields(config_type):
        descriptor = ParameterDescriptor(description=field.metadata['help'],
                                         read_only=field.name not in dynamic)
        value = given(node, field)
        if value is None:
            value = (defaults or {}).get(field.name, field.default)
        values[field.name] = node.declare_parameter(field.name, value, descriptor,
                                                    ignore_override=True).value
    return values


def given(node: Node, field: dataclasses.Field) -> Any:
    """Return the value given for a field's parameter, converted (None: not given).

    Converted to the field's type where that loses nothing (``'4'`` for an integer); a double
    parameter needs a value with a decimal point (``1.0``, not ``1``), as ROS 2 requires of a
    params file; any other value raises ConfigError naming the parameter and the type it takes.
    """
    value = node._parameter_overrides.get(field.name)  # rclpy has no public getter
    if value is None:
        return None
    kind = type(field.default)
    if kind is float and type(value.value) is int:
        raise ConfigError(f'parameter {field.name} takes a double: write '
                          f'{value.value}.0, not {value.value}')
    try:
        return convert(field.name, kind, value.value)
    except ConfigError as exc:
        raise ConfigError(f'parameter {exc}') from None


def warn_unknown_overrides(node: Node, known: Collection[str], where: str) -> None:
    """Warn about each given parameter ``node`` does not declare (a typo in a params file).

    ``where`` says where the parameters are listed (e.g. ``config/sim.yaml``).
    """
    for name in sorted(node._parameter_overrides):
        if node.has_parameter(name):
            continue
        close = difflib.get_close_matches(name, list(known), n=1)
        hint = f' (did you mean {close[0]}?)' if close else ''
        node.get_logger().warn(f'unknown parameter {name!r} ignored{hint}; the parameters '
                               f'of {node.get_name()} are listed in {where}')


def converted(params: list[Parameter], kinds: Mapping[str, type]) -> list[Parameter]:
    """Give each new value the declared type where that loses nothing (``2`` -> ``2.0``).

    A pre-set parameters callback: a value that does not convert is passed on unchanged, and
    then refused with a reason.
    """
    out = []
    for param in params:
        kind = kinds.get(param.name)
        if kind is not None and param.type_ != Parameter.Type.NOT_SET:
            try:
                param = Parameter(param.name, value=convert(param.name, kind, param.value))
            except ConfigError:
                pass
        out.append(param)
    return out


def watch_settings(node: Node, kinds: Mapping[str, type], current: Callable[[], Any],
                   check: Callable[[dict[str, Any]], object],
                   apply: Callable[[dict[str, Any]], None], dynamic: Collection[str]) -> None:
    """Register a node's three parameter callbacks: convert, validate, apply.

    Before a change, each new value is converted to its declared type (:func:`converted`);
    then ``check`` gets every setting as it would be after the change (the fields of the
    dataclass ``current()`` returns, updated) and refuses it by raising a VisnavError or a
    TypeError, whose message becomes the refusal's reason; after an accepted change, ``apply``
    gets the changed values of the ``dynamic`` parameters (never an empty mapping).
    """
    def validate(params: list[Parameter]) -> SetParametersResult:
        values = dataclasses.asdict(current())
        values.update({p.name: p.value for p in params if p.name in values})
        try:
            check(values)
        except (VisnavError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def on_set(params: list[Parameter]) -> None:
        changes = {p.name: p.value for p in params if p.name in dynamic}
        if changes:
            apply(changes)

    node.add_pre_set_parameters_callback(lambda params: converted(params, kinds))
    node.add_on_set_parameters_callback(validate)
    node.add_post_set_parameters_callback(on_set)
