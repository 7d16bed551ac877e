"""cbdi executor: dispatch time-triggered durative actions to the world, safely."""
