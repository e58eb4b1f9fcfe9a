"""Sparkplug B for ``servobus serve --sparkplug GROUP`` (docs/gateway.md "Sparkplug B"):
schema (Tahu's sparkplug_b.proto read into protobuf classes), payload (topics and metrics),
commands (which DCMD writes may run), node (the edge node's MQTT connection)."""
