"""cbdi world service: hosts a domain's simulator for any number of robots.

`service` puts a simulator (entry point `cbdi.simulators`, see `cbdi.simulator`) on the
bus: the epoch clock and its pace, lockstep acknowledgements (`acks`), the request trace
(`trace`) and the end of the run. The recycling grid world is one such simulator, in the
`cbdi-recycling` package.
"""

from cbdi_world.errors import UnknownAgentError, WorldError

__all__ = ["UnknownAgentError", "WorldError"]
