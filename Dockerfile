# Build with the Rust toolchain image, run on slim Debian as a non-root user.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src ./src
COPY api ./api
COPY benches ./benches
RUN cargo build --release --locked --bin contact-sim

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --create-home --home-dir /home/contact contact \
    && mkdir -p /data && chown contact:contact /data
COPY --from=build /src/target/release/contact-sim /usr/local/bin/contact-sim
USER contact
WORKDIR /data
ENTRYPOINT ["contact-sim"]
EXPOSE 8080
VOLUME ["/data"]
CMD ["serve", "--addr", "0.0.0.0:8080", "--data-dir", "/data"]
