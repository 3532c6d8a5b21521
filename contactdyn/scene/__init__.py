"""The scene: a TOML file read and checked into frozen specs, and the key reference (no physics).

``reader`` reads typed values with their key paths (every law reads its keys with it); ``scene_file``
composes a scene from them; ``keys`` and ``keytour`` document every key; ``sanity`` checks a scene
before it runs. ``from contactdyn import load_scene`` loads one."""
