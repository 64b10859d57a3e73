"""The service's routes, one module per concern (FastAPI's "bigger applications" layout); create_app
(server/app.py) includes each module's `router`. Shared parts come from server/deps.py."""
