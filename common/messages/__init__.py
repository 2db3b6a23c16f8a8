"""Typed bus messages, one module per area. See :mod:`common.messages.core` for conventions."""
