"""The live dashboard of an on-line session (issue 19 item 2): ``live`` (what the page shows,
kept by the session's observer; the operator's requests to the supervisor), ``server``
(FastAPI on uvicorn in a thread, loopback and a random token by default, TLS beyond it),
``page`` (the HTML and script)."""
