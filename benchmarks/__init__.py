"""benchmarks: measurements that print figures and assert nothing (``facecast bench ...``).

core             the real-time core: MFCC, streaming inversion, batch HMMI (vs hmmlearn where comparable)
render           rig application and offline rendering speed
server_harness   shared pieces: the model to serve, a server in its own process, ingest and viewers
server_latency   per-stage and end-to-end latency of a live session (the CI latency gate)
server_capacity  sessions and viewers one machine sustains in real time (and over a Redis cluster)
server_soak      RSS growth, frames lost, loop lag and latency over minutes (optionally hostile)
server_redis_transport  Redis stream transport throughput for the cluster
units            unit search, ``facecast say`` to MP4, first frame of a text session
adaptation       speaker adaptation: r(mouth_open) before/after enrolment
"""
