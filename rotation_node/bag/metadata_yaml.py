"""
rosbag2's ``metadata.yaml``: read and written with libyaml where PyYAML has it.

PyYAML's pure-Python emitter and parser took most of the time of converting a
small bag (the metadata is written twice, each topic's QoS profiles parsed
once); libyaml's (``CSafeDumper``, ``CSafeLoader``) write and read the same
YAML, the safe subset, in a fraction of it. Without libyaml, PyYAML's own.
"""
from typing import Any, IO, Union

import yaml

_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
_DUMPER = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)

#: What loading raises for text that is not YAML.
YAMLError = yaml.YAMLError


def load(text: Union[str, bytes, IO]) -> Any:
    """Return the data of a YAML document, as ``yaml.safe_load``."""
    return yaml.load(text, Loader=_LOADER)


def dump(data: Any) -> str:
    """Return the YAML text of ``data``, block style, keys in their order (as ``safe_dump``)."""
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=False)
