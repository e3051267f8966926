"""`--live [HOST:]PORT`: where the live view listens. Localhost unless a host is given explicitly."""

from __future__ import annotations

from dataclasses import dataclass

from hamr_bench.errors import ConfigError

DEFAULT_HOST = "127.0.0.1"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


@dataclass(frozen=True)
class LiveOptions:
    host: str = DEFAULT_HOST
    port: int = 8765

    @property
    def is_local(self) -> bool:
        return self.host in LOCAL_HOSTS

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @classmethod
    def parse(cls, text: str) -> LiveOptions:
        """`PORT`, `HOST:PORT` or `[IPv6]:PORT`; PORT 0 picks a free one."""
        text = text.strip()
        host, port_text = DEFAULT_HOST, text
        if text.startswith("["):
            end = text.find("]:")
            if end < 0:
                raise ConfigError(f"--live {text!r}: expected [IPV6]:PORT")
            host, port_text = text[1:end], text[end + 2:]
        elif ":" in text:
            host, port_text = text.rsplit(":", 1)
        if not host:
            raise ConfigError(f"--live {text!r}: empty host (give PORT alone for localhost)")
        try:
            port = int(port_text)
        except ValueError:
            raise ConfigError(f"--live {text!r}: port {port_text!r} is not a number") from None
        if not 0 <= port <= 65535:
            raise ConfigError(f"--live {text!r}: port {port} outside 0-65535")
        return cls(host, port)
