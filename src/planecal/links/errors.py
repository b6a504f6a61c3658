"""The FD11 link's errors (`planecal.links.fd11`, `planecal.links.sessions`): one-line
messages, raised before anything more is sent."""


class LinkError(RuntimeError):
    """The FD11 link failed (no reply, reference changed, socket error). One-line message."""


class StepLimitError(LinkError):
    """A delta was refused because it changes too much from the previous one; nothing sent."""


class ContactError(LinkError):
    """The first reply does not fit what the controller was stated to hold; nothing more sent."""


class LinkInterrupted(LinkError):
    """The enable signal dropped during an outage; nothing more was sent."""
