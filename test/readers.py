"""Independent readers of our recordings: rosbags with the Jazzy type store and
only what a recording says about the types it holds."""

from rosbags.typesys import Stores, get_types_from_msg, get_typestore


def typestore_of(reader):
    """rosbags' ROS 2 Jazzy type store plus every type the recording's schemas
    define that Jazzy lacks (our ``panel_deploy_interfaces``), from the schema
    text alone, as any reader without this package would read it."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for connection in reader.connections:
        if connection.msgtype not in store.types:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
    return store
