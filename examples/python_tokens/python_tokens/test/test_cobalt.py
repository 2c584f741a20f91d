from python_tokens import exchange


def test_hears_only_its_own_token() -> None:
    exchange.check("cobalt")
