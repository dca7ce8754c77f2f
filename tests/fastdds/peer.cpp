// An independent ROS 2 peer on eProsima Fast DDS 2.9 (Debian's libfastrtps-dev, no ROS),
// the middleware of ROS 2's default RMW (rmw_fastrtps_cpp): publishes camera frames to
// the BEVT node, calls its `reinit` service with the Fast DDS request/reply mapping, and
// records the detections and track status the node publishes.
//
//     bevt_fastdds_peer DOMAIN FRAMES_DIR RATE_HZ WIDTH HEIGHT COUNT X Y W H
//
// FRAMES_DIR holds raw rgb8 frames frame_%05d.rgb of WIDTH x HEIGHT; X Y W H is the box
// sent with `reinit` for frame 0. Frames go out in lock-step: each once the previous one's
// detection has arrived (or 3 s have passed), at most RATE_HZ. Prints one JSON object per line: {"reinit": {...}},
// then {"frame": i, "box": [x, y, w, h], "score": s} per detection and
// {"status": {"frame": i, "state": s, "track_id": n}} per track status received.
//
// Service mapping, as rmw_fastrtps_cpp (rmw_fastrtps_shared_cpp, Humble) does it: the
// request goes to `rq/<service>Request` with no header in the payload; the DDS sample
// identity of the request (writer GUID, sequence number) identifies it, and the
// request's related sample identity carries the GUID of the client's reply reader (the
// sequence number left unknown). The server answers on `rr/<service>Reply` with the
// related sample identity = (that reader GUID, the request's sequence number); the
// client takes a reply as its own when the GUID is its reply reader's (or its request
// writer's) and the sequence number is the one its write returned.

#include "ros_typesPubSubTypes.h"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/common/WriteParams.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

using namespace eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using Clock = std::chrono::steady_clock;

namespace {

// Participant ids (RTPS well-known ports) probed for the node on 127.0.0.1.
constexpr uint32_t kPeerParticipants = 10;
// How long to wait for every endpoint to match the node.
constexpr auto kMatchTimeout = std::chrono::seconds(20);
// Reinit attempts (the first samples may be lost while discovery settles).
constexpr int kReinitAttempts = 20;
// Longest wait for the detection of a frame before the next one is sent.
constexpr auto kFrameTimeout = std::chrono::seconds(3);
// Detections and statuses still read after the last frame.
constexpr auto kDrain = std::chrono::seconds(2);
// Socket buffers: a few 640x360 rgb8 frames.
constexpr uint32_t kSocketBuffer = 4 * 1024 * 1024;

std::string json_string(const std::string& s)
{
    std::string out = "\"";
    for (char c : s)
    {
        switch (c)
        {
            case '"': out += "\\\""; break;
            case '\\': out += "\\\\"; break;
            case '\n': out += "\\n"; break;
            case '\t': out += "\\t"; break;
            default:
                if (static_cast<unsigned char>(c) < 0x20)
                {
                    char buf[8];
                    std::snprintf(buf, sizeof(buf), "\\u%04x", c);
                    out += buf;
                }
                else
                {
                    out += c;
                }
        }
    }
    return out + "\"";
}

std::string guid_string(const rtps::GUID_t& g)
{
    std::ostringstream s;
    s << g;
    return s.str();
}

void emit(const std::string& line)
{
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
}

int fail(int code, const std::string& why)
{
    emit("{\"error\": " + json_string(why) + "}");
    return code;
}

bool read_file(const std::string& path, std::vector<uint8_t>& out)
{
    std::ifstream f(path, std::ios::binary);
    if (!f)
    {
        return false;
    }
    out.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    return true;
}

using Stamp = std::pair<int32_t, uint32_t>;

Stamp now_stamp()
{
    auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::system_clock::now().time_since_epoch()).count();
    return {static_cast<int32_t>(ns / 1000000000), static_cast<uint32_t>(ns % 1000000000)};
}

} // namespace

int main(int argc, char** argv)
{
    if (argc != 11)
    {
        std::fprintf(stderr, "usage: %s DOMAIN FRAMES_DIR RATE_HZ WIDTH HEIGHT COUNT X Y W H\n", argv[0]);
        return 2;
    }
    const uint32_t domain = static_cast<uint32_t>(std::strtoul(argv[1], nullptr, 10));
    const std::string frames = argv[2];
    const double rate = std::strtod(argv[3], nullptr);
    const uint32_t width = static_cast<uint32_t>(std::strtoul(argv[4], nullptr, 10));
    const uint32_t height = static_cast<uint32_t>(std::strtoul(argv[5], nullptr, 10));
    const int count = std::atoi(argv[6]);
    const double init[4] = {std::strtod(argv[7], nullptr), std::strtod(argv[8], nullptr),
                            std::strtod(argv[9], nullptr), std::strtod(argv[10], nullptr)};
    if (rate <= 0.0 || width == 0 || height == 0 || count <= 0)
    {
        return fail(2, "bad arguments");
    }

    // UDP on loopback only (no shared memory, which the node does not speak), unicast
    // discovery of the node's well-known ports on this host.
    DomainParticipantQos pqos;
    pqos.name("bevt_fastdds_peer");
    pqos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.push_back("127.0.0.1");
    udp->sendBufferSize = kSocketBuffer;
    udp->receiveBufferSize = kSocketBuffer;
    pqos.transport().user_transports.push_back(udp);
    for (uint32_t p = 0; p < kPeerParticipants; ++p)
    {
        rtps::Locator_t loc;
        rtps::IPLocator::setIPv4(loc, 127, 0, 0, 1);
        loc.port = 7400 + 250 * domain + 10 + 2 * p;
        pqos.wire_protocol().builtin.initialPeersList.push_back(loc);
    }
    DomainParticipant* dp = DomainParticipantFactory::get_instance()->create_participant(domain, pqos);
    if (dp == nullptr)
    {
        return fail(3, "cannot create a Fast DDS participant");
    }

    TypeSupport t_image(new sensor_msgs::msg::dds_::Image_PubSubType());
    TypeSupport t_dets(new vision_msgs::msg::dds_::Detection2DArray_PubSubType());
    TypeSupport t_status(new bevt_msgs::msg::dds_::TrackStatus_PubSubType());
    TypeSupport t_req(new bevt_msgs::srv::dds_::Reinit_Request_PubSubType());
    TypeSupport t_rep(new bevt_msgs::srv::dds_::Reinit_Response_PubSubType());
    for (auto* t : {&t_image, &t_dets, &t_status, &t_req, &t_rep})
    {
        t->register_type(dp);
    }
    Topic* tp_image = dp->create_topic("rt/image_raw", t_image.get_type_name(), TOPIC_QOS_DEFAULT);
    Topic* tp_dets = dp->create_topic("rt/detections", t_dets.get_type_name(), TOPIC_QOS_DEFAULT);
    Topic* tp_status = dp->create_topic("rt/track_status", t_status.get_type_name(), TOPIC_QOS_DEFAULT);
    Topic* tp_req = dp->create_topic("rq/reinitRequest", t_req.get_type_name(), TOPIC_QOS_DEFAULT);
    Topic* tp_rep = dp->create_topic("rr/reinitReply", t_rep.get_type_name(), TOPIC_QOS_DEFAULT);
    Publisher* pub = dp->create_publisher(PUBLISHER_QOS_DEFAULT);
    Subscriber* sub = dp->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    if (!tp_image || !tp_dets || !tp_status || !tp_req || !tp_rep || !pub || !sub)
    {
        return fail(3, "cannot create topics");
    }

    // Camera: best effort, keep last 1 (rclcpp's sensor-data profile). Services and
    // outputs: reliable, volatile (rmw's service and default profiles).
    DataWriterQos camera_qos = DATAWRITER_QOS_DEFAULT;
    camera_qos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
    camera_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    camera_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    camera_qos.history().depth = 1;
    DataWriterQos request_qos = DATAWRITER_QOS_DEFAULT;
    request_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    request_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    request_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    request_qos.history().depth = 10;
    DataReaderQos reader_qos = DATAREADER_QOS_DEFAULT;
    reader_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    reader_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    reader_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    reader_qos.history().depth = 100;

    DataWriter* w_image = pub->create_datawriter(tp_image, camera_qos);
    DataWriter* w_req = pub->create_datawriter(tp_req, request_qos);
    DataReader* r_dets = sub->create_datareader(tp_dets, reader_qos);
    DataReader* r_status = sub->create_datareader(tp_status, reader_qos);
    DataReader* r_rep = sub->create_datareader(tp_rep, reader_qos);
    if (!w_image || !w_req || !r_dets || !r_status || !r_rep)
    {
        return fail(3, "cannot create readers and writers");
    }

    auto all_matched = [&]() {
        PublicationMatchedStatus ps;
        SubscriptionMatchedStatus ss;
        for (DataWriter* w : {w_image, w_req})
        {
            if (w->get_publication_matched_status(ps) != ReturnCode_t::RETCODE_OK || ps.current_count == 0)
            {
                return false;
            }
        }
        for (DataReader* r : {r_dets, r_status, r_rep})
        {
            if (r->get_subscription_matched_status(ss) != ReturnCode_t::RETCODE_OK || ss.current_count == 0)
            {
                return false;
            }
        }
        return true;
    };
    const auto match_deadline = Clock::now() + kMatchTimeout;
    while (!all_matched())
    {
        if (Clock::now() > match_deadline)
        {
            return fail(3, "no match with the node within 20 s");
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));

    std::map<int, Stamp> stamp_of;
    std::map<Stamp, int> frame_of_stamp;
    sensor_msgs::msg::dds_::Image_ img;
    auto publish = [&](int i) -> bool {
        char name[32];
        std::snprintf(name, sizeof(name), "/frame_%05d.rgb", i);
        if (!read_file(frames + name, img.data_()) || img.data_().size() != size_t(width) * height * 3)
        {
            return false;
        }
        Stamp st = now_stamp();
        stamp_of[i] = st;
        frame_of_stamp[st] = i;
        img.header_().stamp_().sec_(st.first);
        img.header_().stamp_().nanosec_(st.second);
        img.header_().frame_id_("fastdds_camera");
        img.height_(height);
        img.width_(width);
        img.encoding_("rgb8");
        img.is_bigendian_(0);
        img.step_(width * 3);
        return w_image->write(&img);
    };

    std::set<int> answered;
    auto collect = [&]() {
        vision_msgs::msg::dds_::Detection2DArray_ d;
        SampleInfo info;
        while (r_dets->take_next_sample(&d, &info) == ReturnCode_t::RETCODE_OK)
        {
            if (!info.valid_data || d.detections_().empty())
            {
                continue;
            }
            const auto& det = d.detections_()[0];
            const auto& b = det.bbox_();
            Stamp key{d.header_().stamp_().sec_(), d.header_().stamp_().nanosec_()};
            auto it = frame_of_stamp.find(key);
            if (it != frame_of_stamp.end())
            {
                answered.insert(it->second);
            }
            std::ostringstream s;
            s.precision(10);
            s << "{\"frame\": " << (it == frame_of_stamp.end() ? -1 : it->second) << ", \"box\": ["
              << b.center_().position_().x_() - b.size_x_() / 2 << ", "
              << b.center_().position_().y_() - b.size_y_() / 2 << ", " << b.size_x_() << ", "
              << b.size_y_() << "], \"score\": ";
            if (det.results_().empty())
            {
                s << "null";
            }
            else
            {
                s << det.results_()[0].hypothesis_().score_();
            }
            s << "}";
            emit(s.str());
        }
        bevt_msgs::msg::dds_::TrackStatus_ st;
        while (r_status->take_next_sample(&st, &info) == ReturnCode_t::RETCODE_OK)
        {
            if (!info.valid_data)
            {
                continue;
            }
            Stamp key{st.header_().stamp_().sec_(), st.header_().stamp_().nanosec_()};
            auto it = frame_of_stamp.find(key);
            std::ostringstream s;
            s << "{\"status\": {\"frame\": " << (it == frame_of_stamp.end() ? -1 : it->second)
              << ", \"state\": " << int(st.state_()) << ", \"track_id\": " << st.track_id_()
              << ", \"reason\": " << json_string(st.reason_()) << "}}";
            emit(s.str());
        }
    };

    // Frame 0 until the node has it, then reinit on frame 0's stamp.
    bool replied = false;
    bool success = false;
    std::string message;
    std::string identity;
    bool refused = false;
    for (int attempt = 0; attempt < kReinitAttempts && !success; ++attempt)
    {
        if (attempt % 4 == 0)
        {
            if (!publish(0))
            {
                return fail(4, "cannot read or publish frame 0");
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(300));
        }
        bevt_msgs::srv::dds_::Reinit_Request_ req;
        req.x_(init[0]);
        req.y_(init[1]);
        req.width_(init[2]);
        req.height_(init[3]);
        req.stamp_().sec_(stamp_of[0].first);
        req.stamp_().nanosec_(stamp_of[0].second);
        req.frame_id_("");
        rtps::WriteParams wp;
        // As rmw_fastrtps_cpp: "a response is expected" on this reader.
        wp.related_sample_identity().writer_guid() = r_rep->guid();
        if (!w_req->write(&req, wp))
        {
            continue;
        }
        const rtps::SampleIdentity sent = wp.sample_identity();
        const auto end = Clock::now() + std::chrono::milliseconds(500);
        while (Clock::now() < end && !replied)
        {
            bevt_msgs::srv::dds_::Reinit_Response_ rep;
            SampleInfo info;
            while (r_rep->take_next_sample(&rep, &info) == ReturnCode_t::RETCODE_OK)
            {
                const rtps::SampleIdentity& rel = info.related_sample_identity;
                const bool ours = (rel.writer_guid() == r_rep->guid() || rel.writer_guid() == w_req->guid())
                        && rel.sequence_number() == sent.sequence_number();
                if (info.valid_data && ours)
                {
                    replied = true;
                    success = rep.success_();
                    message = rep.message_();
                    identity = guid_string(rel.writer_guid());
                }
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (replied && !success)
        {
            replied = false;
            refused = true;
        }
    }
    if (!replied && !refused)
    {
        emit("{\"reinit\": null}");
        return 4;
    }
    emit("{\"reinit\": {\"success\": " + std::string(success ? "true" : "false") + ", \"message\": "
            + json_string(message) + ", \"related_guid\": " + json_string(identity) + ", \"reply_reader_guid\": "
            + json_string(guid_string(r_rep->guid())) + "}}");

    if (!success)
    {
        return 4;
    }
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate));
    auto next = Clock::now();
    for (int i = 1; i < count; ++i)
    {
        if (!publish(i))
        {
            return fail(4, "cannot read or publish frame " + std::to_string(i));
        }
        // Lock-step: the next frame once this one is answered (or after kFrameTimeout),
        // at most RATE_HZ; a loaded machine then slows the camera instead of making the
        // node drop frames for newer ones.
        const auto frame_deadline = Clock::now() + kFrameTimeout;
        while (answered.count(i) == 0 && Clock::now() < frame_deadline)
        {
            collect();
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        next = std::max(next + period, Clock::now());
        std::this_thread::sleep_until(next);
    }
    const auto end = Clock::now() + kDrain;
    while (Clock::now() < end)
    {
        collect();
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    dp->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(dp);
    return 0;
}
