"""cbdi common library: bus, keys, wire types, clock, service runtime, launcher."""
