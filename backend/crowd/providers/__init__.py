"""The crowd providers: each implements ``backend.crowd.provider.CrowdProvider``."""
