"""Parameter bridges (`bridge.parameters.capability`): parameter clients of other nodes
(`create_parameter_client`, `remove_parameter_client`, `list_parameters`, `get_parameters`,
`set_parameters`, `observe_parameters`) and the daemon's parameter server
(`server_declare_parameter`, `server_set_parameter`, `server_get_parameters`,
`server_undeclare_parameter`)."""

from bridge.parameters.capability import ParameterBridges

__all__ = ["ParameterBridges"]
