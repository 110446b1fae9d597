"""The browser interface: an HTTP + WebSocket server over elicitation sessions (transport only)."""
