"""The bus: one interface (`Bus`), a Zenoh implementation and an in-memory one."""

from cbdi.bus.base import AliveEvent, Bus, Handler, Sample, Subscription, Token
from cbdi.bus.memory import MemoryBus, MemoryNetwork
from cbdi.bus.typed import (
    ErrorSink,
    LogSink,
    inputs,
    messages,
    publish,
    request,
    sequenced_inputs,
    serve,
)
from cbdi.bus.zenoh_bus import BusConfig, ZenohBus, open_bus

__all__ = [
    "AliveEvent",
    "Bus",
    "BusConfig",
    "ErrorSink",
    "Handler",
    "LogSink",
    "MemoryBus",
    "MemoryNetwork",
    "Sample",
    "Subscription",
    "Token",
    "ZenohBus",
    "inputs",
    "messages",
    "open_bus",
    "publish",
    "request",
    "sequenced_inputs",
    "serve",
]
