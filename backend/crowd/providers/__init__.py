"""The crowd providers: each module (or package) implements ``backend.crowd.provider``'s
``CrowdProvider`` for one crowd and offers ``make(settings)``."""
