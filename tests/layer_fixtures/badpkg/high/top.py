"""Something a low module must not import."""


def above() -> str:
    return "high"
