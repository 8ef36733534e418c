# The auv-swarm image: one image for every service (router, world, channel, agents, recorder, collector, viewer).
# Where no image registry answers, build the base locally first:
#   BASE_IMAGE=$(docker/base-image.sh | tail -1) docker-compose build
# Dependencies install offline from docker/wheels/ when it holds wheels (base-image.sh fills it),
# else from the package index. The image keeps rerun's viewer binary (~280 MB): the compose `viewer`
# service runs it to serve the web viewer.
ARG BASE_IMAGE=python:3.11-slim
FROM ${BASE_IMAGE}

ENV PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PATH=/opt/venv/bin:$PATH
COPY docker/wheels/ /tmp/wheels/
COPY pyproject.toml README.md /src/
RUN python3 -m venv /opt/venv \
 && if ls /tmp/wheels/*.whl >/dev/null 2>&1; then FROM_WHEELS="--no-index --find-links /tmp/wheels"; else FROM_WHEELS=""; fi \
 && DEPS=$(python3 -c 'import tomllib; print(" ".join(tomllib.load(open("/src/pyproject.toml", "rb"))["project"]["dependencies"]))') \
 && pip install --no-cache-dir $FROM_WHEELS $DEPS
COPY contract/ /src/contract/
COPY agent/ /src/agent/
COPY channel_sim/ /src/channel_sim/
COPY world/ /src/world/
COPY recorder/ /src/recorder/
COPY bench/ /src/bench/
COPY orchestrator/ /src/orchestrator/
RUN if ls /tmp/wheels/*.whl >/dev/null 2>&1; then FROM_WHEELS="--no-index --find-links /tmp/wheels"; else FROM_WHEELS=""; fi \
 && pip install --no-cache-dir --no-deps $FROM_WHEELS /src \
 && rm -rf /tmp/wheels /src/build \
 && mkdir -p /runs /scenarios /run/auv-swarm
WORKDIR /runs
ENTRYPOINT ["auv-swarm"]
CMD ["--help"]
