"""The live CNC link over OPC UA (issue 18): the virtual machine as an OPC UA server
(:mod:`~millsense.link.server`), the client source that feeds the on-line engine from any
server described by a node map (:mod:`~millsense.link.client`, :mod:`~millsense.link.nodemap`),
and the security around both (:mod:`~millsense.link.security`). Above ``online`` (it builds on
the guard and the session), below ``report``. Node map: docs/opcua.md."""
