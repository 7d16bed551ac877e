"""The service runtime: settings, structured logs and the uvloop/TaskGroup main loop."""

from cbdi.runtime.config import load_config
from cbdi.runtime.log import Log
from cbdi.runtime.service import ServiceContext, ServiceSettings, run_service

__all__ = ["Log", "ServiceContext", "ServiceSettings", "load_config", "run_service"]
