# The graspscape image: the coordinator and the workers (`graspscape worker`).
# Copies only what the package needs, so a local .venv or data folder never enters the image.
FROM python:3.11-slim-bookworm

# pybullet builds from source on some platforms; it needs a C++ compiler there.
RUN apt-get update \
    && apt-get install -y --no-install-recommends build-essential \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY pyproject.toml setup.py README.md alembic.ini ./
COPY shared shared
COPY workers workers
COPY services services
COPY migrations migrations
COPY configs configs
# Editable, so the coordinator finds migrations/ and alembic.ini next to the package sources.
# EXTRAS=rl adds the PPO explorer (CPU torch, stable-baselines3: ~1 GB more); without it a
# `ppo` exploration is refused with a message naming the extra.
ARG EXTRAS=""
RUN pip install --no-cache-dir -e ".${EXTRAS:+[$EXTRAS]}"

ENV GRASPSCAPE_DATABASE__DATA_DIR=/data \
    GRASPSCAPE_API__HOST=0.0.0.0 \
    GRASPSCAPE_API__PORT=8000
VOLUME ["/data"]
EXPOSE 8000
CMD ["graspscape", "serve"]
