"""cbdi world service: the shared recycling world of the paper, for any number of robots.

The pure core (`maps`, `rules`, `chance`, `world`, `physics`) knows nothing of the bus; `service`
puts it on the bus; `scripted` is a scripted robot for demos and end-to-end tests.
"""

from cbdi_world.chance import Chance
from cbdi_world.errors import MapError, UnknownAgentError, WorldError
from cbdi_world.maps import PersonSpec, WorldMap, load_map, parse_map
from cbdi_world.world import AgentSpec, EpochResult, World

__all__ = [
    "AgentSpec",
    "Chance",
    "EpochResult",
    "MapError",
    "PersonSpec",
    "UnknownAgentError",
    "World",
    "WorldError",
    "WorldMap",
    "load_map",
    "parse_map",
]
