"""
The ``rotation_node`` ROS 2 node: the conversion pipeline fed from topics.

- ``program``: the console script (command line, start-up, signals, shut-down);
- ``conversion_node``: the node (parameters, the pipeline, the messages);
- ``qos_adaptation``: the QoS of the input subscriptions, adapted to the publishers;
- ``handoff``: subscriptions and publishers replaced (a new QoS) without loss;
- ``reception``: lost and duplicate messages, from their publication sequence numbers;
- ``diagnostics``: the node's status on ``/diagnostics``.

The package imports the pipeline, the registry, the parameters and the wire
format; nothing below it imports it. Importing it imports nothing: the
program loads the node only once it has said that it is starting.
"""
