"""cbdi's courier domain: robots deliver parcels across an office floor with doors that
close, a battery that drains, and a cart in the corridor (cbdi's second domain)."""
