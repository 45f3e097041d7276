"""Status (compass_sparse.status): the codes are PATH's."""

import compass_sparse as cs


def test_status_codes_match_path():
    assert [int(s) for s in list(cs.Status)[:10]] == list(range(1, 11))
    assert cs.Status.CALLBACK_STOP.path_code() == 6
    assert cs.Status.SOLVED.path_code() == 1
